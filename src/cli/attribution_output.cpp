// magcomp command line: a trained network's attribution, printed and as JSON.
#include "attribution_output.h"

#include <cmath>
#include <cstdio>

#include "common.h"

namespace magcomp::cli {

void print_attribution(const Attribution& a, const std::string& where) {
  const std::string networks =
      a.networks > 1 ? ", averaged over " + std::to_string(a.networks) + " networks" : "";
  std::printf(
      "\ninputs the network leans on (%s on %s, %d shuffles each%s: the rise of its mean squared "
      "error against its target, nT^2; its own %s nT^2 on %ld samples):\n",
      a.method.c_str(), where.c_str(), a.repeats, networks.c_str(),
      figure(a.baseline_mse_nT2, "%.4g").c_str(), static_cast<long>(a.samples));
  for (const InputImportance& i : a.inputs)
    std::printf("  %-24s %12s nT^2 %7.1f%%\n", i.feature.c_str(),
                figure(i.importance_nT2, "%.4g").c_str(), 100 * i.share);
  if (a.channels.empty()) return;
  std::printf(
      "the aircraft's channels it leans on (each with every input that reads it shuffled "
      "together; the model's own inputs left out):\n");
  for (const ChannelImportance& c : a.channels) {
    std::string via;
    if (c.features.size() > 1 || (c.features.size() == 1 && c.features[0] != c.channel)) {
      for (const auto& f : c.features) via += (via.empty() ? " (" : ", ") + f;
      via += ")";
    }
    // Channels that move with it: the network cannot tell them apart.
    std::string alike;
    for (const auto& [other, r] : c.look_alikes) {
      char buf[96];
      std::snprintf(buf, sizeof(buf), "%s%s r=%.3f", alike.empty() ? "; look-alikes: " : ", ",
                    other.c_str(), r);
      alike += buf;
    }
    std::printf("  %-24s %12s nT^2 %7.1f%%%s%s%s\n", c.channel.c_str(),
                figure(c.importance_nT2, "%.4g").c_str(), 100 * c.share, via.c_str(), alike.c_str(),
                c.trajectory ? "  [trajectory: leakage, not a source]" : "");
  }
  if (a.channels.front().trajectory) {
    const ChannelImportance* first = a.first_aircraft_channel();
    if (first)
      std::printf("  first among the aircraft's own channels: %s (%.1f%%)\n",
                  first->channel.c_str(), 100 * first->share);
  }
  if (std::isfinite(a.own_inputs_nT2))
    std::printf("  (the model's own inputs together: %s nT^2%s)\n",
                figure(a.own_inputs_nT2, "%.4g").c_str(),
                a.own_inputs_nT2 > a.channels.front().importance_nT2
                    ? ", above every channel: what it corrects is in the sensors or the terms' "
                      "own inputs (a lag, the coefficients), not in a channel of the aircraft"
                    : "");
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
  nlohmann::json channels = nlohmann::json::array();
  for (const ChannelImportance& c : a.channels) {
    nlohmann::json alikes = nlohmann::json::array();
    for (const auto& [other, r] : c.look_alikes)
      alikes.push_back({{"channel", other}, {"r", json_figure(r)}});
    channels.push_back({{"channel", c.channel},
                        {"features", c.features},
                        {"importance_nT2", json_figure(c.importance_nT2)},
                        {"share", json_figure(c.share)},
                        {"look_alikes", alikes},
                        {"trajectory", c.trajectory}});
  }
  return {{"method", a.method},
          {"baseline_mse_nT2", json_figure(a.baseline_mse_nT2)},
          {"samples", static_cast<long>(a.samples)},
          {"repeats", a.repeats},
          {"networks", a.networks},
          {"inputs", inputs},
          {"channels", channels},
          {"own_inputs_nT2", json_figure(a.own_inputs_nT2)}};
}

}  // namespace magcomp::cli
