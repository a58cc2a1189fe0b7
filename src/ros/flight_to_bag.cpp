// magcomp ROS layer: HDF5 flight -> rosbag (the typed sensor topics and every field's record).
#include <magcomp/AuxChannels.h>
#include <magcomp/FlightRecord.h>
#include <magcomp/FlightSchema.h>
#include <magcomp/ScalarMagnetometer.h>
#include <rosbag/bag.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/MagneticField.h>
#include <sensor_msgs/NavSatFix.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <functional>
#include <memory>
#include <unordered_map>

#include "bag_conversion.h"
#include "magcomp/core/error.h"
#include "magcomp/core/geo/attitude.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/time_base.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/flight_navigation.h"
#include "magcomp/ros/bag_converter.h"
#include "magcomp/ros/bag_writer.h"

namespace magcomp::rosio {

using detail::exists;
using detail::kChunkRows;

namespace {

double first_finite(const FlightData& f, const std::string& name) {
  for (Eigen::Index i0 = 0; i0 < f.size(); i0 += kChunkRows) {
    const Eigen::VectorXd v = f.column_rows(name, i0, std::min(kChunkRows, f.size() - i0));
    for (Eigen::Index k = 0; k < v.size(); ++k) {
      if (std::isfinite(v[k])) return v[k];
    }
  }
  throw Error(f.source() + ": field '" + name + "' has no finite value");
}

// A block of rows [first, first + count) of a flight's columns: where a column lies in memory
// or is read in place, its values there; otherwise those rows read into a buffer. ptr(c)[k] is
// row first + k of column c.
class ChunkedColumns {
 public:
  explicit ChunkedColumns(const FlightData& f) : f_(f), names_(f.names()) {
    for (size_t c = 0; c < names_.size(); ++c) index_[names_[c]] = c;
    buffers_.resize(names_.size());
    pointers_.resize(names_.size(), nullptr);
  }
  void load(Eigen::Index first, Eigen::Index count) {
    for (size_t c = 0; c < names_.size(); ++c) {
      if (const double* in_place = f_.values_in_place(names_[c])) {
        pointers_[c] = in_place + first;
      } else {
        buffers_[c] = f_.column_rows(names_[c], first, count);
        pointers_[c] = buffers_[c].data();
      }
    }
  }
  const double* ptr(size_t c) const { return pointers_[c]; }
  /// The column's values for this block, nullptr when the flight has no such column.
  const double* ptr(const std::string& name) const {
    auto it = index_.find(FlightData::canonical_name(name));
    return it == index_.end() ? nullptr : pointers_[it->second];
  }
  size_t size() const { return names_.size(); }

 private:
  const FlightData& f_;
  std::vector<std::string> names_;
  std::unordered_map<std::string, size_t> index_;
  std::vector<Eigen::VectorXd> buffers_;
  std::vector<const double*> pointers_;
};

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
    has_ins_ = f.has("ins_lat") && f.has("ins_lon") && f.has("ins_alt");
    if (has_ins_ && has_fix_) {  // the MIT schema's INS angles are radians; MagNav.jl's degrees
      ins_scale_ = nav::in_degrees(f.column("ins_lat"), f.column("lat")) ? 1.0 : kRadToDeg;
    } else if (has_ins_) {
      ins_scale_ = std::abs(Eigen::VectorXd(f.column("ins_lat")).mean()) > 1.6 ? 1.0 : kRadToDeg;
    }
    has_ref_ = f.has("mag_1_c");
    for (const auto& s : scalars_)
      c_scalar_.push_back(
          bag.connection<magcomp::ScalarMagnetometer>(std::string(BagTopics::kScalarPrefix) + s));
    c_ref_ = has_ref_ ? bag.connection<magcomp::ScalarMagnetometer>(BagTopics::kReference) : 0;
    for (const auto& b : fluxes_)
      c_flux_.push_back(
          bag.connection<sensor_msgs::MagneticField>(std::string(BagTopics::kFluxPrefix) + b));
    c_imu_ = has_att_ ? bag.connection<sensor_msgs::Imu>(BagTopics::kImu) : 0;
    c_fix_ = has_fix_ ? bag.connection<sensor_msgs::NavSatFix>(BagTopics::kFix) : 0;
    c_ins_ = has_ins_ ? bag.connection<sensor_msgs::NavSatFix>(BagTopics::kInsSolution) : 0;
    c_aux_ = aux_.empty() ? 0 : bag.connection<magcomp::AuxChannels>(BagTopics::kAux);
    for (const auto& s : scalars_) scalar_frames_.push_back(s.substr(0, 5));
    imu_.header.frame_id = "base_link";
    fix_.header.frame_id = "base_link";
    am_.names = aux_;
    am_.values.resize(aux_.size());
  }

  /// Takes the columns of the next block of rows.
  void bind(const ChunkedColumns& chunk) {
    scalar_cols_.clear();
    aux_cols_.clear();
    flux_cols_.clear();
    for (const auto& s : scalars_) scalar_cols_.push_back(chunk.ptr(s));
    for (const auto& a : aux_) aux_cols_.push_back(chunk.ptr(a));
    for (const auto& b : fluxes_)
      flux_cols_.push_back({chunk.ptr(b + "_x"), chunk.ptr(b + "_y"), chunk.ptr(b + "_z")});
    ref_ = chunk.ptr("mag_1_c");
    roll_ = chunk.ptr("ins_roll"), pitch_ = chunk.ptr("ins_pitch"), yaw_ = chunk.ptr("ins_yaw");
    roll_rate_ = chunk.ptr("roll_rate"), pitch_rate_ = chunk.ptr("pitch_rate");
    yaw_rate_ = chunk.ptr("yaw_rate");
    acc_x_ = chunk.ptr("ins_acc_x"), acc_y_ = chunk.ptr("ins_acc_y");
    acc_z_ = chunk.ptr("ins_acc_z");
    lat_ = chunk.ptr("lat"), lon_ = chunk.ptr("lon"), alt_ = chunk.ptr("utm_z");
    ins_lat_ = chunk.ptr("ins_lat"), ins_lon_ = chunk.ptr("ins_lon"),
    ins_alt_ = chunk.ptr("ins_alt");
  }

  /// Writes row i of the bound block, stamped t, on every typed topic; returns the number of
  /// messages.
  long write(Eigen::Index i, const ros::Time& t) {
    sm_.header.stamp = t;
    for (size_t k = 0; k < scalars_.size(); ++k) {
      sm_.header.frame_id = scalar_frames_[k];
      sm_.field_nT = scalar_cols_[k][i];
      bag_.write(c_scalar_[k], t, sm_);
    }
    if (has_ref_) {
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
    if (has_ins_) {
      fix_.header.stamp = t;
      fix_.latitude = ins_lat_[i] * ins_scale_;
      fix_.longitude = ins_lon_[i] * ins_scale_;
      fix_.altitude = ins_alt_[i];
      bag_.write(c_ins_, t, fix_);
    }
    if (!aux_.empty()) {
      am_.header.stamp = t;
      for (size_t k = 0; k < aux_.size(); ++k) am_.values[k] = aux_cols_[k][i];
      bag_.write(c_aux_, t, am_);
    }
    return static_cast<long>(scalars_.size() + fluxes_.size()) + (has_ref_ ? 1 : 0) +
           (has_att_ ? 1 : 0) + (has_fix_ ? 1 : 0) + (has_ins_ ? 1 : 0) + (aux_.empty() ? 0 : 1);
  }

 private:
  static double at(const double* c, Eigen::Index i) { return c ? c[i] : 0.0; }

  // sensor_msgs/Imu of sample i. MIT: yaw clockwise from north, pitch nose up, roll right wing
  // down (NED/FRD). REP 103: base_link (x fwd, y left, z up) in ENU: yaw_enu = 90 deg - yaw,
  // pitch negated; rates in rad/s, accelerations in m/s^2.
  void write_imu(Eigen::Index i, const ros::Time& t) {
    const Eigen::Quaterniond q =
        enu_orientation(roll_[i] * kDegToRad, pitch_[i] * kDegToRad, yaw_[i] * kDegToRad);
    imu_.header.stamp = t;
    imu_.orientation.w = q.w();
    imu_.orientation.x = q.x();
    imu_.orientation.y = q.y();
    imu_.orientation.z = q.z();
    imu_.angular_velocity.x = at(roll_rate_, i) * kDegToRad;
    imu_.angular_velocity.y = -at(pitch_rate_, i) * kDegToRad;
    imu_.angular_velocity.z = -at(yaw_rate_, i) * kDegToRad;
    imu_.linear_acceleration.x = at(acc_x_, i);
    imu_.linear_acceleration.y = at(acc_y_, i);
    imu_.linear_acceleration.z = at(acc_z_, i);
    bag_.write(c_imu_, t, imu_);
  }

  BagWriter& bag_;
  std::vector<std::string> scalars_, fluxes_, aux_, scalar_frames_;
  bool has_att_ = false, has_fix_ = false, has_ref_ = false, has_ins_ = false;
  double ins_scale_ = 1.0;  // INS angles to degrees
  std::vector<const double*> scalar_cols_, aux_cols_;
  std::vector<std::array<const double*, 3>> flux_cols_;
  const double *ref_ = nullptr, *roll_ = nullptr, *pitch_ = nullptr, *yaw_ = nullptr;
  const double *roll_rate_ = nullptr, *pitch_rate_ = nullptr, *yaw_rate_ = nullptr;
  const double *acc_x_ = nullptr, *acc_y_ = nullptr, *acc_z_ = nullptr;
  const double *lat_ = nullptr, *lon_ = nullptr, *alt_ = nullptr;
  const double *ins_lat_ = nullptr, *ins_lon_ = nullptr, *ins_alt_ = nullptr;
  std::vector<uint32_t> c_scalar_, c_flux_;
  uint32_t c_ref_ = 0, c_imu_ = 0, c_fix_ = 0, c_ins_ = 0, c_aux_ = 0;
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
    const uint32_t c_record = bag.connection<magcomp::FlightRecord>(BagTopics::kRecord);
    TypedTopics typed(f, bag);
    ChunkedColumns chunk(f);
    magcomp::FlightRecord rec;
    rec.values.resize(chunk.size());
    for (Eigen::Index first = 0; first < f.size(); first += kChunkRows) {
      const Eigen::Index count = std::min(kChunkRows, f.size() - first);
      chunk.load(first, count);
      typed.bind(chunk);
      for (Eigen::Index k = 0; k < count; ++k) {
        const ros::Time t = stamp_of(year, doy, tt[first + k]);
        rec.header.stamp = t;
        rec.header.seq = static_cast<uint32_t>(first + k);
        for (size_t c = 0; c < chunk.size(); ++c) rec.values[c] = chunk.ptr(c)[k];
        bag.write(c_record, t, rec);
        rep.messages += 1 + typed.write(k, t);
      }
      f.drop_mapped_pages(first + count);  // the rows written need not stay resident
    }
    bag.close();
  } catch (...) {
    std::remove(tmp.c_str());
    throw;
  }
  commit_temporary(tmp, bag_path, {f.source()});
  return rep;
}

}  // namespace magcomp::rosio
