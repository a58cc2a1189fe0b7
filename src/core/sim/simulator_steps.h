// magcomp simulator (internal to src/core/sim): the Simulator that assembles one flight, step by
// step. simulator.cpp runs it (the Earth field, the channels, the aircraft, the truth),
// simulator_sensors.cpp holds the sensors and the hidden effects on them,
// simulator_navigation.cpp the navigation map and the drifting INS.
#pragma once

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/sim/electrical.h"
#include "magcomp/core/sim/simulator.h"
#include "magcomp/core/sim/trajectory.h"

namespace magcomp::sim::steps {

using Vectors = std::vector<Eigen::Vector3d>;

// Per-sensor aircraft field: B_a = p + M B + E dB/dt (body frame, nT; E in s).
struct AircraftField {
  Eigen::Vector3d permanent_nT;
  Eigen::Matrix3d induced;
  Eigen::Matrix3d eddy_s;
};

inline bool applies(const HiddenEffect& e, const SensorMount& m) {
  if (e.sensors.empty()) return e.type == "fluxgate" ? m.vector : !m.vector;
  return std::find(e.sensors.begin(), e.sensors.end(), m.name) != e.sensors.end();
}

inline double rms(const Eigen::VectorXd& v) { return std::sqrt(v.array().square().mean()); }
inline double stdev(const Eigen::VectorXd& v) {
  return std::sqrt((v.array() - v.mean()).square().mean());
}

// The Earth field along the track, in the body frame (FLU) and as totals, nT.
struct EarthAlongTrack {
  Eigen::VectorXd tt, anomaly, diurnal, igrf_total, earth_total;
  Vectors body;  // Earth field in base_link
  Vectors rate;  // its rate of change, nT/s
};

// One simulation's state: the steps below run in this order, and draw from one random stream in
// this order (the same seed gives the same file).
class Simulator {
 public:
  Simulator(const Scenario& s, const Igrf& igrf)
      : s_(s),
        igrf_(igrf),
        tr_(fly(s)),
        n_(tr_.size()),
        dt_(1.0 / s.sample_rate_hz),
        rng_(s.seed * 2654435761ULL + 5),
        normal_(0.0, 1.0) {}

  Simulation run() {
    earth_field();
    channels_ = simulate_channels(tr_, s_.seed, s_.aircraft_states);
    ins_ = ins_quantities();
    begin_truth();
    draw_aircraft();
    y_ << YAML::Key << "sensors" << YAML::Value << YAML::BeginMap;
    for (size_t k = 0; k < sensor_mounts().size(); ++k) sensor(k);
    y_ << YAML::EndMap;
    hidden_effects_truth();
    reference_and_survey_fields();
    if (s_.nav_ins_drift) drifting_ins();
    return std::move(sim_);
  }

 private:
  void earth_field();
  void navigation_map(const Eigen::MatrixXd& ground_nT);
  void drifting_ins();
  std::map<std::string, Eigen::VectorXd> ins_quantities() const;
  const Eigen::VectorXd& source(const std::string& name) const {
    auto it = channels_.find(name);
    return it != channels_.end() ? it->second : ins_.at(name);
  }
  void begin_truth();
  void draw_aircraft();
  Vectors sensor_field(const AircraftField& a) const;
  void sensor(size_t index);
  void fluxgate(const SensorMount& m, const Vectors& field);
  void scalar(const SensorMount& m, const Vectors& field);
  // One effect's contribution to a scalar sensor (nT), adding its body field to hidden_vec or
  // its scalar part to scalar_extra.
  Eigen::VectorXd hidden_contribution(const HiddenEffect& e, const SensorMount& m,
                                      const Vectors& field, Vectors* hidden_vec,
                                      Eigen::VectorXd* scalar_extra) const;
  void hidden_effects_truth();
  void hidden_effect_truth(const HiddenEffect& e);
  void reference_and_survey_fields();
  void ins_fields();

  const Scenario& s_;
  const Igrf& igrf_;  ///< the main field, given by the caller
  const Track tr_;
  const Eigen::Index n_;
  const double dt_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_;
  EarthAlongTrack earth_;
  std::map<std::string, Eigen::VectorXd> channels_, ins_;
  std::vector<AircraftField> aircraft_;
  Simulation sim_;
  YAML::Emitter y_;
};

}  // namespace magcomp::sim::steps
