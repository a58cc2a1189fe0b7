// magcomp ROS layer: MIT-schema HDF5 flights <-> rosbags.
#pragma once

#include <ros/time.h>

#include <string>

#include "magcomp/core/flight_data.h"

namespace magcomp::rosio {

/// Topics written by flight_to_bag (and read by the nodes).
struct BagTopics {
  static constexpr const char* kSchema = "/magcomp/flight_schema";  ///< FlightSchema, once
  static constexpr const char* kRecord = "/magcomp/flight_record";  ///< FlightRecord, every sample
  static constexpr const char* kScalarPrefix =
      "/magcomp/scalar/";  ///< + mag_k_uc: ScalarMagnetometer
  static constexpr const char* kReference = "/magcomp/reference";   ///< mag_1_c: ScalarMagnetometer
  static constexpr const char* kFluxPrefix = "/magcomp/fluxgate/";  ///< + flux_x: MagneticField (T)
  static constexpr const char* kImu = "/magcomp/ins/imu";           ///< sensor_msgs/Imu (ENU, FLU)
  static constexpr const char* kFix = "/magcomp/ins/fix";           ///< sensor_msgs/NavSatFix
  static constexpr const char* kAux = "/magcomp/aux";  ///< AuxChannels: cur_*, vol_*, diurnal
};

/// Stamp of a sample: midnight UTC of (year, day of year) + tt seconds.
ros::Time stamp_of(int year, int doy, double tt_s);

struct ConvertReport {
  long samples = 0;
  long fields = 0;
  long messages = 0;
};

/// Writes the flight as a bag: typed sensor topics for the nodes, plus every field of every
/// sample on /magcomp/flight_record so that bag_to_flight gives back the file bit for bit.
/// Stamps from year, doy and tt. Written to a temporary file and renamed; refuses to overwrite
/// unless `force`. Throws magcomp::Error naming the file and field (e.g. NaN in tt).
ConvertReport flight_to_bag(const FlightData& flight, const std::string& bag_path, bool force);

/// Reads a bag written by flight_to_bag back into a flight (every field, every sample, exact).
FlightData bag_to_flight(const std::string& bag_path);

}  // namespace magcomp::rosio
