// magcomp diagnose: rank the physical effects the model misses, and say which --term to add.
#include <cstdio>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "magcomp/core/diagnose.h"
#include "magcomp/core/error.h"
#include "subcommands.h"

namespace magcomp::cli {

void add_diagnose(CLI::App& app) {
  auto* cmd = app.add_subcommand("diagnose", "rank candidate missing effects on held-out data");
  auto data = std::make_shared<std::string>();
  auto model_path = std::make_shared<std::string>();
  auto truth = std::make_shared<std::string>("mag_1_c");
  auto json_path = std::make_shared<std::string>();
  auto top = std::make_shared<int>(10);
  cmd->add_option("--data", *data, "flight HDF5 file")->required();
  cmd->add_option("--model", *model_path, "model YAML (fitted or not)")->required();
  cmd->add_option("--truth", *truth, "reference field (default mag_1_c)");
  cmd->add_option("--json", *json_path, "write the diagnosis JSON here");
  cmd->add_option("--top", *top, "rows to print (default 10)");
  cmd->callback([=] {
    const Model model = load_model_yaml(*model_path);
    const FlightData flight = read_flight_h5(*data);
    const Diagnosis dx = diagnose(model, flight, *truth);
    std::printf("model: %s with %s, terms:", model.scalar.c_str(), model.vector.c_str());
    for (const auto& t : model.terms) std::printf(" %s", t.c_str());
    std::printf("\nsplit: %s\n", dx.split.c_str());
    std::printf(
        "baseline: held-out error std %.3f nT (line means removed) on %ld samples; fit on %ld\n\n",
        dx.baseline_std_nT, static_cast<long>(dx.heldout_samples),
        static_cast<long>(dx.fit_samples));
    std::printf("%-4s %-22s %11s %11s %9s  %-26s %s\n", "rank", "term (--term)", "std_before",
                "std_after", "explained", "estimate", "effect");
    for (size_t k = 0; k < dx.candidates.size() && static_cast<int>(k) < *top; ++k) {
      const Candidate& c = dx.candidates[k];
      std::printf("%-4zu %-22s %11.3f %11.3f %8.1f%%  %-26s %s\n", k + 1, c.term.c_str(),
                  dx.baseline_std_nT, c.std_after_nT, 100 * c.explained_fraction,
                  c.estimate.c_str(), c.effect.c_str());
    }
    if (!dx.candidates.empty()) {
      const Candidate& best = dx.candidates.front();
      std::printf(
          "\nto add the top effect:\n  magcomp calibrate --data %s --model %s --term %s --out "
          "NEW.yaml\n",
          data->c_str(), model_path->c_str(), best.term.c_str());
    }
    std::printf("\nresidual vs channel (held-out, line means removed), strongest first:\n");
    std::printf("  %-14s %8s %9s %8s\n", "channel", "pearson", "spearman", "MI_bits");
    for (size_t k = 0; k < dx.associations.size() && k < 8; ++k) {
      const auto& a = dx.associations[k];
      std::printf("  %-14s %8.3f %9.3f %8.3f\n", a.channel.c_str(), a.pearson, a.spearman,
                  a.mutual_information_bits);
    }
    for (const auto& note : dx.notes) std::printf("note: %s\n", note.c_str());
    if (!json_path->empty()) {
      nlohmann::json j;
      j["data"] = *data;
      j["model"] = *model_path;
      j["truth"] = *truth;
      j["split"] = dx.split;
      j["baseline_std_nT"] = dx.baseline_std_nT;
      j["heldout_samples"] = dx.heldout_samples;
      j["fit_samples"] = dx.fit_samples;
      j["candidates"] = nlohmann::json::array();
      for (const auto& c : dx.candidates) {
        j["candidates"].push_back({{"term", c.term},
                                   {"effect", c.effect},
                                   {"channel", c.channel},
                                   {"std_after_nT", c.std_after_nT},
                                   {"explained_fraction", c.explained_fraction},
                                   {"estimate", c.estimate}});
      }
      j["associations"] = nlohmann::json::array();
      for (const auto& a : dx.associations) {
        j["associations"].push_back({{"channel", a.channel},
                                     {"pearson", a.pearson},
                                     {"spearman", a.spearman},
                                     {"mutual_information_bits", a.mutual_information_bits}});
      }
      j["notes"] = dx.notes;
      std::ofstream f(*json_path);
      if (!f) throw Error(*json_path + ": cannot write JSON");
      f << j.dump(2) << "\n";
    }
  });
}

}  // namespace magcomp::cli
