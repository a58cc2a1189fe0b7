// magcomp simulate: a flight in the MIT schema, plus the truth of what was simulated.
#include <chrono>
#include <iostream>

#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/output_guard.h"
#include "magcomp/core/sim/random_effects.h"
#include "magcomp/core/sim/simulator.h"
#include "subcommands.h"

namespace magcomp::cli {

void add_simulate(CLI::App& app) {
  auto* cmd =
      app.add_subcommand("simulate", "simulate a flight (with hidden effects) from a scenario");
  auto scenario = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>();
  auto seed = std::make_shared<long long>(-1);
  auto aircraft_seed = std::make_shared<long long>(-1);
  auto random_seed = std::make_shared<long long>(-1);
  auto random_count = std::make_shared<int>(1);
  cmd->add_option("--scenario", *scenario, "scenario YAML (see config/scenarios/)")->required();
  cmd->add_option("--out", *out, "flight HDF5 to write (truth beside it: .truth.yaml, .truth.h5)")
      ->required();
  cmd->add_option("--seed", *seed, "override the scenario's seed");
  cmd->add_option("--aircraft-seed", *aircraft_seed,
                  "override the scenario's aircraft_seed (the aircraft's own sources; keep it and "
                  "change --seed for the next flight of the same aircraft)");
  cmd->add_option("--random-effects", *random_seed,
                  "add hidden effects drawn at random from this seed (kinds, channels, shapes, "
                  "sizes 0.3-3 nT rms on mag_5_uc; listed in the truth YAML)");
  cmd->add_option("--random-count", *random_count, "how many random effects (default 1)");
  cmd->callback([=] {
    const auto t0 = std::chrono::steady_clock::now();
    OutputGuard guard({{"--scenario", *scenario}});
    guard.add_output("--out", *out);
    guard.add_output("--out (truth)", sim::truth_path(*out, "h5"));
    guard.add_output("--out (truth)", sim::truth_path(*out, "yaml"));
    sim::Scenario s = sim::load_scenario(*scenario);
    if (*seed >= 0) s.seed = static_cast<unsigned>(*seed);
    if (*aircraft_seed >= 0) s.aircraft_seed = *aircraft_seed;
    if (*random_seed >= 0) {
      if (*random_count < 1) throw Error("--random-count: must be >= 1");
      for (const auto& e : sim::random_effects(s, static_cast<unsigned>(*random_seed),
                                               *random_count, Igrf::installed()))
        s.hidden.push_back(e);
    }
    const sim::Simulation result = sim::simulate(s, Igrf::installed());
    sim::write_simulation(result, *out, {*scenario});
    const double secs =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << "simulated " << result.flight.size() << " samples ("
              << result.flight.size() / 36000.0 << " h at 10 Hz), " << result.flight.names().size()
              << " fields, " << s.hidden.size() << " hidden effect(s) in " << secs << " s\n"
              << "wrote " << *out << ", " << sim::truth_path(*out, "yaml") << ", "
              << sim::truth_path(*out, "h5") << "\n";
  });
}

}  // namespace magcomp::cli
