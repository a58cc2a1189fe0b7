// magcomp ROS layer: HDF5 <-> rosbag conversion.
#include "magcomp/ros/bag_converter.h"

#include <magcomp/AuxChannels.h>
#include <magcomp/FlightRecord.h>
#include <magcomp/FlightSchema.h>
#include <magcomp/ScalarMagnetometer.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/MagneticField.h>
#include <sensor_msgs/NavSatFix.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <ctime>
#include <fstream>

#include "magcomp/core/error.h"
#include "magcomp/core/file_io.h"
#include "magcomp/core/time_base.h"
#include "magcomp/ros/bag_check.h"
#include "magcomp/ros/bag_writer.h"

namespace magcomp::rosio {

FlightData bag_to_flight_checked(const std::string& bag_path);

namespace {

// The serialised bytes of a bag message, read with every length checked against them (a
// corrupt length in ROS's own deserialiser allocates whatever it says before failing).
class RawMessage {
 public:
  explicit RawMessage(const rosbag::MessageInstance& m) : bytes_(m.size()) {
    ros::serialization::OStream out(bytes_.data(), static_cast<uint32_t>(bytes_.size()));
    m.write(out);
  }
  bool u32(uint32_t* v) {
    if (bytes_.size() - pos_ < 4) return false;
    std::memcpy(v, bytes_.data() + pos_, 4);
    pos_ += 4;
    return true;
  }
  bool skip_header() {  // std_msgs/Header: seq, stamp, frame_id; the seq is kept
    uint32_t stamp[2], len;
    if (!u32(&seq_) || !u32(&stamp[0]) || !u32(&stamp[1]) || !u32(&len)) return false;
    return skip(len);
  }
  bool skip(uint64_t n) {
    if (bytes_.size() - pos_ < n) return false;
    pos_ += n;
    return true;
  }
  bool doubles(std::vector<double>* out) {
    uint32_t n;
    if (!u32(&n) || (bytes_.size() - pos_) / 8 < n) return false;
    out->resize(n);
    if (n > 0) std::memcpy(out->data(), bytes_.data() + pos_, 8ull * n);  // empty: no pointer
    pos_ += 8ull * n;
    return true;
  }
  bool strings(std::vector<std::string>* out) {
    uint32_t n;
    if (!u32(&n) || (bytes_.size() - pos_) / 4 < n) return false;
    out->clear();
    for (uint32_t k = 0; k < n; ++k) {
      uint32_t len;
      if (!u32(&len) || bytes_.size() - pos_ < len) return false;
      out->emplace_back(reinterpret_cast<const char*>(bytes_.data() + pos_), len);
      pos_ += len;
    }
    return true;
  }
  uint32_t seq() const { return seq_; }

 private:
  std::vector<uint8_t> bytes_;
  size_t pos_ = 0;
  uint32_t seq_ = 0;
};

}  // namespace
namespace {

constexpr double kDeg = M_PI / 180.0;

bool exists(const std::string& path) { return std::ifstream(path).good(); }

double first_finite(const FlightData& f, const std::string& name) {
  const auto v = f.column(name);
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    if (std::isfinite(v[i])) return v[i];
  }
  throw Error(f.source() + ": field '" + name + "' has no finite value");
}

}  // namespace

ros::Time stamp_of(int year, int doy, double tt_s) {
  int64_t sec = 0, nsec = 0;
  epoch_of(year, doy, tt_s, &sec, &nsec);
  ros::Time t;
  t.sec = static_cast<uint32_t>(sec);
  t.nsec = static_cast<uint32_t>(nsec);
  return t;
}

namespace {

// The date of a flight's stamps: year and day of year from its fields, and every tt finite.
std::pair<int, int> stamp_date(const FlightData& f) {
  const int year = static_cast<int>(f.has("year") ? first_finite(f, "year") : -1);
  const int doy = static_cast<int>(f.has("doy") ? first_finite(f, "doy") : -1);
  if (year < 1970)
    throw Error(f.source() + ": field 'year' missing or before 1970 (stamps need it)");
  if (doy < 1 || doy > 366) throw Error(f.source() + ": field 'doy' missing or not in 1..366");
  const auto tt = f.tt();
  for (Eigen::Index i = 0; i < tt.size(); ++i) {
    if (!std::isfinite(tt[i])) {
      throw Error(f.source() + ": field 'tt' is NaN at sample " + std::to_string(i) +
                  "; it cannot be stamped");
    }
  }
  return {year, doy};
}

// The typed sensor topics of one flight: which fields feed them (scalars mag_N_uc, fluxgates
// flux_X_{x,y,z}, named aux values), the column pointers resolved once (a name lookup per
// message costs more than the message), the connections registered once in a fixed order, and
// the messages reused from sample to sample.
class TypedTopics {
 public:
  TypedTopics(const FlightData& f, BagWriter& bag) : bag_(bag) {
    for (const auto& name : f.names()) {
      if (name.size() == 8 && name.rfind("mag_", 0) == 0 && name.substr(5) == "_uc")
        scalars_.push_back(name);
      if (name.size() == 8 && name.rfind("flux_", 0) == 0 && name.substr(6) == "_x") {
        const std::string base = name.substr(0, 6);
        if (f.has(base + "_y") && f.has(base + "_z")) fluxes_.push_back(base);
      }
      // Named values: the electrical channels, diurnal, line, and the INS values a neural
      // stage may take as features (the compensator reads any feature by name from here).
      if (name.rfind("cur_", 0) == 0 || name.rfind("vol_", 0) == 0 || name == "diurnal" ||
          name == "line" || name == "baro" || name == "ins_vn" || name == "ins_vw" ||
          name == "ins_vu" || name == "ins_roll" || name == "ins_pitch" || name == "ins_yaw")
        aux_.push_back(name);
    }
    has_att_ = f.has("ins_roll") && f.has("ins_pitch") && f.has("ins_yaw");
    has_fix_ = f.has("lat") && f.has("lon");
    auto col = [&](const std::string& name) {
      return f.has(name) ? f.column(name).data() : nullptr;
    };
    for (const auto& s : scalars_) scalar_cols_.push_back(col(s));
    for (const auto& a : aux_) aux_cols_.push_back(col(a));
    for (const auto& b : fluxes_)
      flux_cols_.push_back({col(b + "_x"), col(b + "_y"), col(b + "_z")});
    ref_ = col("mag_1_c");
    roll_ = col("ins_roll"), pitch_ = col("ins_pitch"), yaw_ = col("ins_yaw");
    roll_rate_ = col("roll_rate"), pitch_rate_ = col("pitch_rate"), yaw_rate_ = col("yaw_rate");
    acc_x_ = col("ins_acc_x"), acc_y_ = col("ins_acc_y"), acc_z_ = col("ins_acc_z");
    lat_ = col("lat"), lon_ = col("lon"), alt_ = col("utm_z");
    for (const auto& s : scalars_)
      c_scalar_.push_back(
          bag.connection<magcomp::ScalarMagnetometer>(std::string(BagTopics::kScalarPrefix) + s));
    c_ref_ = ref_ ? bag.connection<magcomp::ScalarMagnetometer>(BagTopics::kReference) : 0;
    for (const auto& b : fluxes_)
      c_flux_.push_back(
          bag.connection<sensor_msgs::MagneticField>(std::string(BagTopics::kFluxPrefix) + b));
    c_imu_ = has_att_ ? bag.connection<sensor_msgs::Imu>(BagTopics::kImu) : 0;
    c_fix_ = has_fix_ ? bag.connection<sensor_msgs::NavSatFix>(BagTopics::kFix) : 0;
    c_aux_ = aux_.empty() ? 0 : bag.connection<magcomp::AuxChannels>(BagTopics::kAux);
    for (const auto& s : scalars_) scalar_frames_.push_back(s.substr(0, 5));
    imu_.header.frame_id = "base_link";
    fix_.header.frame_id = "base_link";
    am_.names = aux_;
    am_.values.resize(aux_.size());
  }

  /// Writes sample i, stamped t, on every typed topic; returns the number of messages.
  long write(Eigen::Index i, const ros::Time& t) {
    sm_.header.stamp = t;
    for (size_t k = 0; k < scalars_.size(); ++k) {
      sm_.header.frame_id = scalar_frames_[k];
      sm_.field_nT = scalar_cols_[k][i];
      bag_.write(c_scalar_[k], t, sm_);
    }
    if (ref_) {
      sm_.header.frame_id = "mag_1";
      sm_.field_nT = ref_[i];
      bag_.write(c_ref_, t, sm_);
    }
    fm_.header.stamp = t;
    for (size_t k = 0; k < fluxes_.size(); ++k) {
      fm_.header.frame_id = fluxes_[k];
      fm_.magnetic_field.x = flux_cols_[k][0][i] * 1e-9;  // REP 145: Tesla
      fm_.magnetic_field.y = flux_cols_[k][1][i] * 1e-9;
      fm_.magnetic_field.z = flux_cols_[k][2][i] * 1e-9;
      bag_.write(c_flux_[k], t, fm_);
    }
    if (has_att_) write_imu(i, t);
    if (has_fix_) {
      fix_.header.stamp = t;
      fix_.latitude = lat_[i];
      fix_.longitude = lon_[i];
      fix_.altitude = alt_ ? alt_[i] : NAN;  // above the WGS-84 ellipsoid
      fix_.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_UNKNOWN;
      bag_.write(c_fix_, t, fix_);
    }
    if (!aux_.empty()) {
      am_.header.stamp = t;
      for (size_t k = 0; k < aux_.size(); ++k) am_.values[k] = aux_cols_[k][i];
      bag_.write(c_aux_, t, am_);
    }
    return static_cast<long>(scalars_.size() + fluxes_.size()) + (ref_ ? 1 : 0) +
           (has_att_ ? 1 : 0) + (has_fix_ ? 1 : 0) + (aux_.empty() ? 0 : 1);
  }

 private:
  static double at(const double* c, Eigen::Index i) { return c ? c[i] : 0.0; }

  // sensor_msgs/Imu of sample i. MIT: yaw clockwise from north, pitch nose up, roll right wing
  // down (NED/FRD). REP 103: base_link (x fwd, y left, z up) in ENU: yaw_enu = 90 deg - yaw,
  // pitch negated; rates in rad/s, accelerations in m/s^2.
  void write_imu(Eigen::Index i, const ros::Time& t) {
    const Eigen::Quaterniond q =
        Eigen::AngleAxisd(M_PI / 2 - yaw_[i] * kDeg, Eigen::Vector3d::UnitZ()) *
        Eigen::AngleAxisd(-pitch_[i] * kDeg, Eigen::Vector3d::UnitY()) *
        Eigen::AngleAxisd(roll_[i] * kDeg, Eigen::Vector3d::UnitX());
    imu_.header.stamp = t;
    imu_.orientation.w = q.w();
    imu_.orientation.x = q.x();
    imu_.orientation.y = q.y();
    imu_.orientation.z = q.z();
    imu_.angular_velocity.x = at(roll_rate_, i) * kDeg;
    imu_.angular_velocity.y = -at(pitch_rate_, i) * kDeg;
    imu_.angular_velocity.z = -at(yaw_rate_, i) * kDeg;
    imu_.linear_acceleration.x = at(acc_x_, i);
    imu_.linear_acceleration.y = at(acc_y_, i);
    imu_.linear_acceleration.z = at(acc_z_, i);
    bag_.write(c_imu_, t, imu_);
  }

  BagWriter& bag_;
  std::vector<std::string> scalars_, fluxes_, aux_, scalar_frames_;
  bool has_att_ = false, has_fix_ = false;
  std::vector<const double*> scalar_cols_, aux_cols_;
  std::vector<std::array<const double*, 3>> flux_cols_;
  const double *ref_ = nullptr, *roll_ = nullptr, *pitch_ = nullptr, *yaw_ = nullptr;
  const double *roll_rate_ = nullptr, *pitch_rate_ = nullptr, *yaw_rate_ = nullptr;
  const double *acc_x_ = nullptr, *acc_y_ = nullptr, *acc_z_ = nullptr;
  const double *lat_ = nullptr, *lon_ = nullptr, *alt_ = nullptr;
  std::vector<uint32_t> c_scalar_, c_flux_;
  uint32_t c_ref_ = 0, c_imu_ = 0, c_fix_ = 0, c_aux_ = 0;
  sensor_msgs::Imu imu_;
  sensor_msgs::NavSatFix fix_;
  magcomp::ScalarMagnetometer sm_;
  sensor_msgs::MagneticField fm_;
  magcomp::AuxChannels am_;
};

}  // namespace

ConvertReport flight_to_bag(const FlightData& f, const std::string& bag_path, bool force) {
  if (!force && exists(bag_path)) {
    throw Error(bag_path + ": exists; pass --force to overwrite");
  }
  const auto [year, doy] = stamp_date(f);
  const auto tt = f.tt();
  check_output_path(bag_path, {f.source()});
  const std::string tmp = temporary_path(bag_path);
  ConvertReport rep;
  rep.samples = f.size();
  rep.fields = static_cast<long>(f.names().size());
  try {
    BagWriter bag(tmp);
    // Lossless record of every field: the schema (names) once, then one record per sample.
    magcomp::FlightSchema schema;
    schema.header.stamp = stamp_of(year, doy, tt[0]);
    schema.names = f.names();
    bag.write(bag.connection<magcomp::FlightSchema>(BagTopics::kSchema), schema.header.stamp,
              schema);
    rep.messages++;
    std::vector<const double*> cols;
    for (const auto& name : f.names()) cols.push_back(f.column(name).data());
    const uint32_t c_record = bag.connection<magcomp::FlightRecord>(BagTopics::kRecord);
    TypedTopics typed(f, bag);
    magcomp::FlightRecord rec;
    rec.values.resize(cols.size());
    for (Eigen::Index i = 0; i < f.size(); ++i) {
      const ros::Time t = stamp_of(year, doy, tt[i]);
      rec.header.stamp = t;
      rec.header.seq = static_cast<uint32_t>(i);
      for (size_t c = 0; c < cols.size(); ++c) rec.values[c] = cols[c][i];
      bag.write(c_record, t, rec);
      rep.messages += 1 + typed.write(i, t);
    }
    bag.close();
  } catch (...) {
    std::remove(tmp.c_str());
    throw;
  }
  commit_temporary(tmp, bag_path, {f.source()});
  return rep;
}

FlightData bag_to_flight(const std::string& bag_path) {
  try {
    return bag_to_flight_checked(bag_path);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {  // rosbag or deserialisation: name the file
    throw Error(bag_path + ": not a readable rosbag (" + e.what() + ")");
  }
}

FlightData bag_to_flight_checked(const std::string& bag_path) {
  if (!exists(bag_path)) throw Error(bag_path + ": file not found or not readable");
  check_bag_structure(bag_path);
  rosbag::Bag bag;
  try {
    bag.open(bag_path, rosbag::bagmode::Read);
  } catch (const rosbag::BagException& e) {
    throw Error(bag_path + ": not a readable rosbag (" + e.what() + ")");
  }
  std::vector<std::string> names;
  {
    rosbag::View v(bag, rosbag::TopicQuery(std::string(BagTopics::kSchema)));
    for (const auto& m : v) {
      if (m.getDataType() != "magcomp/FlightSchema") continue;
      RawMessage raw(m);
      if (!raw.skip_header() || !raw.strings(&names)) {
        throw Error(bag_path + ": the message on '" + BagTopics::kSchema + "' is corrupt");
      }
      break;
    }
  }
  if (names.empty()) {
    throw Error(
        bag_path + ": topic '" + BagTopics::kSchema +
        "' not found: only bags written by magcomp convert can be turned back into flights");
  }
  std::vector<std::vector<double>> cols(names.size());
  rosbag::View v(bag, rosbag::TopicQuery(std::string(BagTopics::kRecord)));
  long expected_seq = 0;
  std::vector<double> values;
  for (const auto& m : v) {
    if (m.getDataType() != "magcomp/FlightRecord") continue;
    RawMessage raw(m);
    if (!raw.skip_header() || !raw.doubles(&values)) {
      throw Error(bag_path + ": record " + std::to_string(expected_seq) + " on '" +
                  BagTopics::kRecord + "' is corrupt");
    }
    if (values.size() != names.size()) {
      throw Error(bag_path + ": a record on '" + BagTopics::kRecord + "' has " +
                  std::to_string(values.size()) + " values, the schema names " +
                  std::to_string(names.size()));
    }
    if (static_cast<long>(raw.seq()) != expected_seq) {
      throw Error(bag_path + ": record " + std::to_string(expected_seq) +
                  " missing or out of order on '" + BagTopics::kRecord + "'");
    }
    ++expected_seq;
    for (size_t c = 0; c < names.size(); ++c) cols[c].push_back(values[c]);
  }
  bag.close();
  FlightData f;
  f.set_source(bag_path);
  for (size_t c = 0; c < names.size(); ++c) {
    f.set(names[c],
          Eigen::Map<Eigen::VectorXd>(cols[c].data(), static_cast<Eigen::Index>(cols[c].size())));
  }
  return f;
}

}  // namespace magcomp::rosio
