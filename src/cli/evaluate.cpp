// magcomp evaluate: a fitted model's error against a reference, overall and per line.
#include <cstdio>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "common.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluation.h"
#include "subcommands.h"

namespace magcomp::cli {

void add_evaluate(CLI::App& app) {
  auto* cmd = app.add_subcommand("evaluate", "compare a fitted model with a reference field");
  auto data = std::make_shared<std::string>();
  auto model_path = std::make_shared<std::string>();
  auto truth = std::make_shared<std::string>("mag_1_c");
  auto json_path = std::make_shared<std::string>();
  cmd->add_option("--data", *data, "flight HDF5 file")->required();
  cmd->add_option("--model", *model_path, "fitted model YAML")->required();
  cmd->add_option("--truth", *truth, "reference field (default mag_1_c)");
  cmd->add_option("--json", *json_path, "write the evaluation JSON here");
  cmd->callback([=] {
    const Model model = load_model_yaml(*model_path);
    if (!model.fitted()) throw Error(*model_path + ": model has no coefficients; run calibrate");
    const FlightData flight = read_flight_h5(*data);
    const Evaluation ev = evaluate_model(model, flight, *truth);
    std::printf("%-10s %8s %12s %10s\n", "line", "n", "rmse_nT", "std_nT");
    for (const auto& l : ev.per_line) {
      std::printf("%-10.2f %8ld %12.3f %10.3f\n", l.line, static_cast<long>(l.n), l.rmse_nT,
                  l.std_nT);
    }
    std::printf("%-10s %8ld %12.3f %10.3f\n", "all", static_cast<long>(ev.n), ev.rmse_nT,
                ev.std_nT);
    if (ev.nan_samples > 0) {
      std::printf("(%ld samples with NaN in the model inputs or the reference were skipped)\n",
                  static_cast<long>(ev.nan_samples));
    }
    if (!json_path->empty()) {
      nlohmann::json j;
      j["data"] = *data;
      j["model"] = *model_path;
      j["truth"] = *truth;
      j["n"] = ev.n;
      j["nan_samples"] = ev.nan_samples;
      j["rmse_nT"] = ev.rmse_nT;
      j["std_nT"] = ev.std_nT;
      j["per_line"] = nlohmann::json::array();
      for (const auto& l : ev.per_line) {
        j["per_line"].push_back(
            {{"line", l.line}, {"n", l.n}, {"rmse_nT", l.rmse_nT}, {"std_nT", l.std_nT}});
      }
      std::ofstream f(*json_path);
      if (!f) throw Error(*json_path + ": cannot write JSON");
      f << j.dump(2) << "\n";
    }
  });
}

}  // namespace magcomp::cli
