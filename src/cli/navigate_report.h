// magcomp navigate: one navigated measurement series, and the report page written from it
// (navigate_report.cpp).
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/flight_navigation.h"
#include "magcomp/core/nav/flight_run.h"

namespace magcomp::cli {

/// One measurement series navigated: the run, its scores, its name.
struct Navigated {
  /// Its JSON key: "" (the figures at the top), "baseline", "static", "uncompensated".
  std::string key;
  std::string name;
  nav::FlightRun run;
  nav::NavigationScores scores;
};

/// DIR/tracks.h5 (truth, INS and filter tracks in degrees at each step, errors and the filter's
/// horizontal covariance in metres, the measurement anomaly_nT and the innovations in nT; the
/// map), DIR/navigation.json (the figures `j`), then the HTML page. `inputs`: the paths no
/// output may overwrite.
void write_navigation_report(const std::string& dir, const nav::FlightSamples& samples,
                             const Navigated& n, const Eigen::VectorXd& anomaly_nT,
                             const nav::AnomalyMap& map, const nlohmann::json& j,
                             const std::vector<std::string>& inputs);

}  // namespace magcomp::cli
