// magcomp benchmark: does a network's attribution name the channel of an effect TL misses? Each
// run draws one hidden effect at random (sim/random_effects, as scripts/bench_discovery) on the
// random_base flight of one aircraft, flies it three times (train, early-stop, explain), fits TL
// on the first, trains an MLP on what TL leaves with every aircraft channel as an input (by
// default correcting TL's coefficients at every sample, with the group lasso on each channel's
// inputs, neural.training.channel_sparsity 0.01), and ranks the inputs by permutation importance on
// the third flight (core/neural/attribution). Each channel enters raw and through causal filters
// (default a 2 s and a 100 s low-pass, a flex's lag of a second or two and effects far slower than
// the window, and a 0.5 s high-pass, the rate of change an inductive pickup follows),
// and the channels are ranked with all their inputs shuffled together (Attribution::channels). A
// run counts when the first-ranked channel of the aircraft (Attribution::first_aircraft_channel: a
// position or an earth-frame velocity ranked above it is the trajectory, leakage, and is passed
// over) is one the effect acts through (for an effect of no channel, a lag: when the model's own
// inputs together outweigh every channel), and also counts ("alike") when the effect's channel is
// among that channel's look-alikes (channels whose values follow it, |r| >= 0.95, which the network
// cannot tell apart); the first-ranked single input is printed beside it. Prints one line per run
// and the shares over the predictable runs (effects of recorded channels). With "diagnose", each
// run's first flight is also diagnosed from TL with and without the attribution
// (DiagnoseOptions::network_channels), on the channels-only and on the full search, and the run
// counts where the first accepted term reads the effect's channel. Usage: magcomp_bench_attribution
// SCENARIO.yaml TL_MODEL.yaml [runs] [first_seed] [epochs]
//        [low-pass time constants, s, comma-separated, or "none"; a token that is not a number
//        is a transform each channel also enters through; default 2,100,hp(0.5)] [diagnose]
//        [ensemble=K: K networks trained per run (seeds 1..K), their attributions averaged
//        (average_attributions); the MLP's error printed is their mean] [mode=M: the network's
//        mode, coefficients (default), residual or joint] [sparsity=L: the group lasso on the
//        channels' inputs, neural.training.channel_sparsity (default 0.01; 0 off)]
//        [cut=C: neural.training.channel_cut, the refit of the kept channels (default 0: none)]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <sstream>
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
    std::vector<std::string> lowpass_s;
    {
      std::stringstream list(argc > 6 ? argv[6] : "2,100,hp(0.5)");
      for (std::string tau; std::getline(list, tau, ',');)
        if (!tau.empty() && tau != "none") lowpass_s.push_back(tau);
    }
    bool with_diagnose = false;
    int ensemble = 1;  // networks trained per run (seeds 1..K), their attributions averaged
    std::string mode = "coefficients";  // the network's mode (coefficients, residual, joint)
    double sparsity = 0.01;             // neural.training.channel_sparsity
    double cut = 0.0;                   // neural.training.channel_cut
    for (int k = 7; k < argc; ++k) {
      const std::string arg = argv[k];
      if (arg == "diagnose") with_diagnose = true;
      if (arg.rfind("ensemble=", 0) == 0) ensemble = std::max(1, std::atoi(arg.c_str() + 9));
      if (arg.rfind("mode=", 0) == 0) mode = arg.substr(5);
      if (arg.rfind("sparsity=", 0) == 0) sparsity = std::atof(arg.c_str() + 9);
      if (arg.rfind("cut=", 0) == 0) cut = std::atof(arg.c_str() + 4);
    }
    const Igrf& igrf = Igrf::installed();
    // diagnose: runs whose first accepted term reads the effect's channel, by search (0
    // channels-only, 1 full) and without / with the network's channels.
    int dx_counted = 0, dx_named[2][2] = {{0, 0}, {0, 0}};
    const std::string dir = std::string(std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp") +
                            "/magcomp_bench_attribution";
    std::filesystem::create_directories(dir);
    int counted = 0, first_right = 0, top3_right = 0, alike_right = 0;
    const auto t0 = std::chrono::steady_clock::now();
    // "own": the model's own inputs together outweigh the first channel.
    std::printf("%4s %8s %8s %5s %-16s %6s %3s  %-22s  %s\n", "run", "TL nT", "MLP nT", "first",
                "first channel", "share", "", "first input", "effect");
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
      spec.mode = parse_mode(mode, "bench");
      spec.window = 5;
      spec.features = {"tl_anomaly", "tl_correction", "dir_x", "dir_y", "dir_z"};
      for (const std::string& c : source_fields(m, flights[0], "mag_1_c", true, nullptr)) {
        if (is_position_channel(c)) continue;
        spec.features.push_back(c);
        // A number is a low-pass's time constant; any other token a transform of the term
        // language (d: the rate of change, which an inductive pickup follows).
        for (const auto& tau : lowpass_s)
          spec.features.push_back(
              c + "|" + (std::strtod(tau.c_str(), nullptr) > 0 ? "lp(" + tau + ")" : tau));
      }
      spec.training.epochs = epochs;
      spec.training.patience = 5;
      spec.training.channel_sparsity = sparsity;
      spec.training.channel_cut = cut;
      m.neural = spec;
      std::vector<Attribution> each;
      double tl_nT = NAN, nn_nT = 0;
      for (int e = 0; e < ensemble; ++e) {
        const std::string out = dir + "/run" + std::to_string(r) + "_seed" + std::to_string(e + 1);
        m.neural->training.seed = static_cast<std::uint64_t>(e + 1);
        train_bundle(m, {flights[0]}, {flights[1]}, out, false);
        const Model trained = load_model_yaml(out);
        Model tl_only = trained;
        tl_only.neural.reset();
        tl_nT = evaluate_model(tl_only, flights[2], "mag_1_c", false).std_nT;
        nn_nT += evaluate_model(trained, flights[2], "mag_1_c", false).std_nT / ensemble;
        each.push_back(permutation_importance(trained, flights[2]));
      }
      const Attribution a = average_attributions(each);
      // An effect of no channel (a lag) is named when the model's own inputs together outweigh
      // every channel of the aircraft; any other by the first-ranked channel.
      const bool own_first =
          std::isfinite(a.own_inputs_nT2) &&
          (a.channels.empty() || a.own_inputs_nT2 > a.channels.front().importance_nT2);
      // The first of the aircraft's own channels: a position or an earth-frame velocity is the
      // trajectory (leakage), never a source of the aircraft's field.
      const ChannelImportance* first_ch = a.first_aircraft_channel();
      const std::string top = first_ch ? first_ch->channel : "";
      const bool right = truth.empty() ? own_first : truth.count(top) > 0;
      // The effect's channel among the first-ranked channel's look-alikes (channels that move
      // with it, which the network cannot tell apart).
      bool alike = right;
      for (size_t i = 0; !alike && first_ch && i < first_ch->look_alikes.size(); ++i)
        alike = truth.count(first_ch->look_alikes[i].first) > 0;
      bool in_top3 = right;
      for (size_t i = 0, seen = 0; i < a.channels.size() && seen < 3; ++i) {
        if (a.channels[i].trajectory) continue;
        ++seen;
        in_top3 = in_top3 || truth.count(a.channels[i].channel) > 0;
      }
      if (predictable) {
        ++counted;
        first_right += right;
        top3_right += in_top3;
        alike_right += alike;
      }
      std::string dx_line;
      if (with_diagnose && !truth.empty()) {
        Model from = tl;
        fit_model(from, {&flights[0]});
        std::vector<NetworkChannel> network;
        for (const ChannelImportance& c : a.channels) network.push_back({c.channel, c.share});
        if (predictable) ++dx_counted;
        for (int full = 0; full < 2; ++full) {
          for (int with = 0; with < 2; ++with) {
            DiagnoseOptions o;
            o.full_search = full == 1;
            o.explainable_share = false;
            if (with) o.network_channels = network;
            const Diagnosis dx = diagnose(from, flights[0], "mag_1_c", o);
            std::string named = "none";
            if (!dx.candidates.empty() && dx.candidates.front().accepted) {
              named = dx.candidates.front().term.text();
              bool reads = false;
              for (const std::string& c : term_channels(dx.candidates.front().term))
                reads = reads || truth.count(c) > 0;
              if (predictable) dx_named[full][with] += reads;
              named += reads ? " (yes)" : " (no)";
            }
            dx_line += std::string(dx_line.empty() ? "" : " | ") +
                       (full ? "full" : "channels-only") + (with ? "+network: " : ": ") + named;
          }
        }
      }
      std::printf("%4u %8.3f %8.3f %5s %-16s %5.1f%% %3s  %-22s  %s%s\n", r, tl_nT, nn_nT,
                  right ? "yes" : (alike ? "alike" : (in_top3 ? "top3" : "no")), top.c_str(),
                  first_ch ? 100 * first_ch->share : 0.0, own_first ? "own" : "",
                  a.inputs.front().feature.c_str(), described.c_str(),
                  predictable ? "" : " (not predictable: not counted)");
      if (!dx_line.empty()) std::printf("     diagnose: %s\n", dx_line.c_str());
      std::fflush(stdout);
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf(
        "\n%d predictable runs: the first-ranked channel of the aircraft carries the effect in %d "
        "(%.0f %%), it or "
        "one of its look-alikes in %d (%.0f %%), one of the first three in %d (%.0f %%); %.0f s\n",
        counted, first_right, counted ? 100.0 * first_right / counted : 0.0, alike_right,
        counted ? 100.0 * alike_right / counted : 0.0, top3_right,
        counted ? 100.0 * top3_right / counted : 0.0, s);
    if (with_diagnose)
      std::printf(
          "diagnose, the first accepted term reads the effect's channel (%d predictable runs "
          "with a channel): channels-only %d, with the network %d; full search %d, with the "
          "network %d\n",
          dx_counted, dx_named[0][0], dx_named[0][1], dx_named[1][0], dx_named[1][1]);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
}
