// magcomp ROS layer: MIT-schema HDF5 flights <-> rosbags.
#pragma once

#include <ros/time.h>

#include <string>

#include "magcomp/core/io/flight_data.h"

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
  /// sensor_msgs/NavSatFix of the INS's own position (ins_lat, ins_lon, ins_alt): what a
  /// navigator corrects; magcomp/ins/fix is the reference (GPS) position.
  static constexpr const char* kInsSolution = "/magcomp/ins/solution";
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

/// The same written straight to an HDF5 flight file a block of rows at a time, read from the bag
/// in one pass without rosbag's index (memory: a block per field, the time base and one chunk
/// of the bag, whatever the flight's length), atomically (FlightH5Writer); `h5_path` must not be
/// the bag. The file equals write_flight_h5(bag_to_flight(bag_path)). A bag with compressed
/// chunks or records out of order in the file is read through rosbag's index instead.
ConvertReport bag_to_h5(const std::string& bag_path, const std::string& h5_path);

}  // namespace magcomp::rosio
