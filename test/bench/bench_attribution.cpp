// magcomp benchmark: does a network's attribution name the channel of an effect TL misses? Each
// run draws one hidden effect at random (sim/random_effects, as scripts/bench_discovery) on the
// random_base flight of one aircraft, flies it three times (train, early-stop, explain), fits TL
// on the first, trains a residual MLP on what TL leaves with every aircraft channel as an input,
// and ranks the inputs by permutation importance on the third flight (core/neural/attribution).
// A run counts when the first-ranked input is a channel the effect acts through. Prints one line
// per run and the share over the predictable runs (effects of recorded channels).
// Usage: magcomp_bench_attribution SCENARIO.yaml TL_MODEL.yaml [runs] [first_seed] [epochs]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/residual_floor.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/neural/attribution.h"
#include "magcomp/core/sim/random_effects.h"
#include "magcomp/core/sim/simulator.h"
#include "magcomp/neural/trainer.h"

int main(int argc, char** argv) {
  using namespace magcomp;
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s SCENARIO.yaml TL_MODEL.yaml [runs] [first_seed] [epochs]\n",
                 argv[0]);
    return 2;
  }
  try {
    const sim::Scenario base0 = sim::load_scenario(argv[1]);
    const Model tl = load_model_yaml(argv[2]);
    const int runs = argc > 3 ? std::atoi(argv[3]) : 20;
    const unsigned first = argc > 4 ? static_cast<unsigned>(std::atoi(argv[4])) : 1;
    const int epochs = argc > 5 ? std::atoi(argv[5]) : 20;
    const Igrf& igrf = Igrf::installed();
    const std::string dir = std::string(std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp") +
                            "/magcomp_bench_attribution";
    std::filesystem::create_directories(dir);
    int counted = 0, first_right = 0, top3_right = 0;
    const auto t0 = std::chrono::steady_clock::now();
    std::printf("%4s %8s %8s %5s %-22s %6s  %s\n", "run", "TL nT", "MLP nT", "first", "first input",
                "share", "effect");
    for (int k = 0; k < runs; ++k) {
      const unsigned r = first + static_cast<unsigned>(k);
      sim::Scenario base = base0;
      base.aircraft_seed = 5000 + r;
      base.seed = 1000 + 2 * r;
      const std::vector<sim::HiddenEffect> effects = sim::random_effects(base, r, 1, igrf);
      std::set<std::string> truth;
      bool predictable = true;
      std::string described;
      for (const auto& e : effects) {
        described += sim::describe(e);
        predictable = predictable && sim::predictable(e);
        for (const std::string& c : {e.channel, e.channel2})
          if (!c.empty()) truth.insert(c);
      }
      std::vector<FlightData> flights;
      for (int f = 0; f < 3; ++f) {
        sim::Scenario s = base;
        s.hidden = effects;
        s.seed = base.seed + static_cast<unsigned>(f);
        flights.push_back(sim::simulate(s, igrf).flight);
        flights.back().set_source("run" + std::to_string(r) + "_flight" + std::to_string(f));
      }
      Model m = tl;
      fit_model(m, {&flights[0]});
      NeuralSpec spec;
      spec.architecture = parse_architecture("mlp", "bench");
      spec.mode = parse_mode("residual", "bench");
      spec.window = 5;
      spec.features = {"tl_anomaly", "tl_correction", "dir_x", "dir_y", "dir_z"};
      for (const std::string& c : source_fields(m, flights[0], "mag_1_c", true, nullptr))
        if (!is_position_channel(c)) spec.features.push_back(c);
      spec.training.epochs = epochs;
      spec.training.patience = 5;
      m.neural = spec;
      const std::string out = dir + "/run" + std::to_string(r);
      train_bundle(m, {flights[0]}, {flights[1]}, out, false);
      const Model trained = load_model_yaml(out);
      Model tl_only = trained;
      tl_only.neural.reset();
      const double tl_nT = evaluate_model(tl_only, flights[2], "mag_1_c", false).std_nT;
      const double nn_nT = evaluate_model(trained, flights[2], "mag_1_c", false).std_nT;
      const Attribution a = permutation_importance(trained, flights[2]);
      const std::string top = a.inputs.front().feature;
      const bool right = truth.count(top) > 0;
      bool in_top3 = false;
      for (size_t i = 0; i < a.inputs.size() && i < 3; ++i)
        in_top3 = in_top3 || truth.count(a.inputs[i].feature) > 0;
      if (predictable) {
        ++counted;
        first_right += right;
        top3_right += in_top3;
      }
      std::printf("%4u %8.3f %8.3f %5s %-22s %5.1f%%  %s%s\n", r, tl_nT, nn_nT,
                  right ? "yes" : (in_top3 ? "top3" : "no"), top.c_str(),
                  100 * a.inputs.front().share, described.c_str(),
                  predictable ? "" : " (not predictable: not counted)");
      std::fflush(stdout);
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf(
        "\n%d predictable runs: the first-ranked input carries the effect in %d (%.0f %%), one of "
        "the first three in %d (%.0f %%); %.0f s\n",
        counted, first_right, counted ? 100.0 * first_right / counted : 0.0, top3_right,
        counted ? 100.0 * top3_right / counted : 0.0, s);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
}
