// magcomp tests: shipped scenarios, simulated once per test binary.
#pragma once

#include <map>
#include <string>

#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/sim/simulator.h"
#include "magcomp/core/stream/streaming_compensator.h"
#include "test_util.h"

namespace magcomp::test {

/// The simulation of config/scenarios/<name>.yaml (cached).
inline const sim::Simulation& scenario(const std::string& name) {
  static std::map<std::string, sim::Simulation> cache;
  auto it = cache.find(name);
  if (it == cache.end()) {
    const sim::Scenario s =
        sim::load_scenario(source_dir() + "/config/scenarios/" + name + ".yaml");
    it = cache.emplace(name, sim::simulate(s, Igrf::installed())).first;
  }
  return it->second;
}

/// The shipped TL model for the simulated flights, plus extra terms, calibrated on `flight`.
inline Model calibrated_tl(const FlightData& flight, const std::vector<std::string>& extra = {}) {
  Model m = load_model_yaml(source_dir() + "/config/models/tl_sim.yaml");
  for (const auto& t : extra) m.add_term(t);
  fit_model(m, {&flight});
  return m;
}

/// The user's loop's starting model for the 1002 scenarios (config/models/tl_reference.yaml):
/// TL fitted against mag_1_c on the training lines; not fitted yet.
inline Model reference_tl(const FlightData&) {
  return load_model_yaml(source_dir() + "/config/models/tl_reference.yaml");
}

/// Pooled std (line means removed) of the model's error against mag_1_c on the whole flight, nT.
inline double tl_std(const FlightData& flight, const std::vector<std::string>& extra = {}) {
  return evaluate_model(calibrated_tl(flight, extra), flight, "mag_1_c").std_nT;
}

/// Sample i of a flight as the stream sees it: mag_5_uc, flux_c, and the named channels.
inline StreamSample sample_at(const FlightData& f, Eigen::Index i,
                              const std::vector<std::string>& channels = {}) {
  StreamSample s;
  s.t_s = f.tt()[i];
  s.scalar_nT = f.column("mag_5_uc")[i];
  s.vector_nT = {f.column("flux_c_x")[i], f.column("flux_c_y")[i], f.column("flux_c_z")[i]};
  for (const auto& c : channels) s.channels.push_back(f.column(c)[i]);
  return s;
}

}  // namespace magcomp::test
