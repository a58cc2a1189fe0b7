// magcomp command line: a trained network's attribution, printed and as JSON.
#include "attribution_output.h"

#include <cstdio>

#include "common.h"

namespace magcomp::cli {

void print_attribution(const Attribution& a, const std::string& where) {
  std::printf(
      "\ninputs the network leans on (%s on %s, %d shuffles each: the rise of its mean squared "
      "error against its target, nT^2; its own %s nT^2 on %ld samples):\n",
      a.method.c_str(), where.c_str(), a.repeats, figure(a.baseline_mse_nT2, "%.4g").c_str(),
      static_cast<long>(a.samples));
  for (const InputImportance& i : a.inputs)
    std::printf("  %-24s %12s nT^2 %7.1f%%\n", i.feature.c_str(),
                figure(i.importance_nT2, "%.4g").c_str(), 100 * i.share);
}

nlohmann::json attribution_json(const Attribution& a) {
  nlohmann::json inputs = nlohmann::json::array();
  for (const InputImportance& i : a.inputs) {
    nlohmann::json lines = nlohmann::json::array();
    for (const auto& [line, rise] : i.per_line_nT2)
      lines.push_back({{"line", line}, {"importance_nT2", json_figure(rise)}});
    inputs.push_back({{"feature", i.feature},
                      {"importance_nT2", json_figure(i.importance_nT2)},
                      {"share", json_figure(i.share)},
                      {"per_line", lines}});
  }
  return {{"method", a.method},
          {"baseline_mse_nT2", json_figure(a.baseline_mse_nT2)},
          {"samples", static_cast<long>(a.samples)},
          {"repeats", a.repeats},
          {"inputs", inputs}};
}

}  // namespace magcomp::cli
