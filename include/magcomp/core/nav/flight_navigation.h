// magcomp: a recorded flight as the navigation filter sees it: the true and the INS tracks from
// the flight's fields, and the measured anomaly (a model's compensation less the main and the
// diurnal field). What `magcomp navigate` runs, and what a navigator node must reproduce online.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/streaming_track.h"

namespace magcomp::nav {

/// The true track (lat, lon deg; alt, utm_z or msl m; roll/pitch/yaw deg, else the INS's) and the
/// INS track (ins_lat, ins_lon in rad or deg; ins_alt m; ins_roll/pitch/yaw deg), both at the
/// flight's sample step. Throws magcomp::Error naming the file and the missing field.
struct FlightTracks {
  NavTrack truth, ins;
  double mean_alt_m = 0.0;  ///< the true track's mean altitude, m
};
FlightTracks flight_tracks(const FlightData& flight);

/// The flight's true height, m: utm_z (GPS height above the WGS-84 ellipsoid: the datum of the
/// maps, the IGRF and the navigation filter), else msl (older files' alt). One vertical datum
/// throughout: the map's continuation, the map reference and the filter's track all read it.
/// Throws magcomp::Error naming the file.
Eigen::VectorXd flight_height_m(const FlightData& flight);

/// A flight's rows as the navigator's inputs, stamped with the rows' tt (s), from the fields
/// flight_tracks() reads. Nothing is checked here: the navigator refuses and counts a sample it
/// cannot use (invalid_ins_reason).
struct FlightSamples {
  std::vector<InsSample> ins;    ///< the INS solution
  std::vector<InsSample> truth;  ///< the true track
  double dt_s = 0.1;             ///< the flight's sample step (median of tt's steps), s
  double mean_alt_m = NAN;       ///< mean true altitude over the rows where it is valid, m
};
FlightSamples flight_samples(const FlightData& flight);

/// The anomaly of a total field along the flight, nT: total_nT (one per row) less the IGRF at the
/// true position and, when the flight has it, the diurnal field (geo/anomaly.h).
Eigen::VectorXd flight_anomaly_nT(const FlightData& flight, const Eigen::VectorXd& total_nT);

/// The measured anomaly, nT: the model's compensated field (its raw scalar when `uncompensated`)
/// less the IGRF at the true position and, when the flight has it, the diurnal field.
Eigen::VectorXd measured_anomaly_nT(const FlightData& flight, const Model& model,
                                    bool uncompensated = false);

/// Whether an INS latitude or longitude column is in degrees, judged against the true column in
/// degrees (within 1 of its mean).
bool in_degrees(const Eigen::VectorXd& angle, const Eigen::VectorXd& reference_deg);

/// An INS latitude or longitude column in radians: degrees are recognised against the true
/// column in degrees (the MIT schema's INS angles are radians, MagNav.jl's files use degrees).
Eigen::VectorXd radians_like(const Eigen::VectorXd& angle, const Eigen::VectorXd& reference_deg);

}  // namespace magcomp::nav
