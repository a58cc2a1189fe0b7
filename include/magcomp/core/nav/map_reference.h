// magcomp: the map as the reference field. Where no reference magnetometer flies (no stinger, no
// calibration box at altitude), what a clean magnetometer would read along the track is the
// anomaly map there plus the main field (IGRF) plus the diurnal variation: a reference column that
// calibrate, evaluate and diagnose use as they use mag_1_c. The map's own error (and its
// interpolation error) stays in it: it is part of every figure scored against it.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/nav/anomaly_map.h"

namespace magcomp::nav {

/// The positions a map reference is read at: the true track (lat, lon: GPS), the INS solution
/// (ins_lat, ins_lon), or given positions (the navigation filter's).
enum class MapTrack { Truth, Ins, Given };

/// Whether a reference or --truth value names a map, "map:PATH" (PATH returned), rather than a
/// field of the flight.
bool names_map(const std::string& spec, std::string* path = nullptr);

/// The map reference along a flight, and what went into it.
struct MapReference {
  Eigen::VectorXd field_nT;        ///< map + IGRF + diurnal, nT; NaN where the map does not cover
  long off_map = 0;                ///< rows without a value (off the map, or no position)
  double map_altitude_m = NAN;     ///< the map's altitude as used (after any continuation)
  double flight_altitude_m = NAN;  ///< the flight's mean height above the ellipsoid
  std::vector<std::string> notes;  ///< what a user must know (a map above the flight, ...)
};

/// The reference along `flight` from `map` (continued up to the flight's mean height when the
/// map lies below it; a map above the flight is used as it is, with a note), the IGRF at each
/// row's position, height and date, and the flight's `diurnal` field when it has one.
/// `lat_rad`/`lon_rad` give the positions for MapTrack::Given (one per row, NaN: none).
MapReference map_reference(const FlightData& flight, AnomalyMap map, MapTrack track,
                           const Igrf& igrf, const Eigen::VectorXd* lat_rad = nullptr,
                           const Eigen::VectorXd* lon_rad = nullptr);

}  // namespace magcomp::nav
