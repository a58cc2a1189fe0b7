// magcomp ROS layer: topics into the stream aligner.
#include "magcomp/ros/input_stream.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "magcomp/ros/callback_guard.h"

namespace magcomp::rosio {
namespace {
constexpr double kNanoteslaPerTesla = 1e9;      // REP 145 fluxgates are in tesla
constexpr double kMountRetryPeriod_s = 0.2;     // a missing mount is looked up 5 times a second
constexpr double kMountWarningPeriod_s = 10.0;  // and warned about every 10 s
}  // namespace

InputStream::InputStream(ros::NodeHandle nh, const Topics& topics, const AlignerSettings& settings,
                         uint32_t queue, bool tcp_nodelay, std::string base_frame,
                         Callbacks callbacks)
    : topics_(topics),
      aligner_(settings),
      cb_(std::move(callbacks)),
      base_frame_(std::move(base_frame)) {
  const ros::TransportHints hints = ros::TransportHints().tcpNoDelay(tcp_nodelay);
  sub_scalar_ = nh.subscribe(topics_.scalar, queue, &InputStream::on_scalar, this, hints);
  sub_vector_ = nh.subscribe(topics_.vector, queue, &InputStream::on_vector, this, hints);
  sub_aux_ = nh.subscribe(topics_.aux, queue, &InputStream::on_aux, this, hints);
  sub_fix_ = nh.subscribe(topics_.fix, queue, &InputStream::on_fix, this, hints);
  if (!topics_.reference.empty()) {
    sub_ref_ = nh.subscribe(topics_.reference, queue, &InputStream::on_reference, this, hints);
  }
  if (!topics_.end_of_stream.empty()) {
    sub_end_ = nh.subscribe(topics_.end_of_stream, 10, &InputStream::on_end, this);
  }
  tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
}

double InputStream::rel(const ros::Time& s) {
  if (base_sec_ < 0) base_sec_ = s.sec;
  return static_cast<double>(static_cast<int64_t>(s.sec) - base_sec_) + 1e-9 * s.nsec;
}

ros::Time InputStream::stamp(double t) const {
  const double whole = std::floor(t);
  int64_t nsec = std::llround((t - whole) * 1e9);
  const int64_t sec =
      std::max<int64_t>(0, base_sec_) + static_cast<int64_t>(whole) + nsec / 1000000000LL;
  nsec %= 1000000000LL;
  ros::Time out;
  out.sec = static_cast<uint32_t>(sec);
  out.nsec = static_cast<uint32_t>(nsec);
  return out;
}

void InputStream::on_scalar(const magcomp::ScalarMagnetometer::ConstPtr& m) {
  guarded("magcomp input", &callback_errors_, [&] {
    last_scalar_wall_s_ = ros::WallTime::now().toSec();
    const auto r = aligner_.add_scalar(rel(m->header.stamp), m->field_nT, last_scalar_wall_s_);
    if (r == StreamAligner::ScalarResult::kJumpedBack && cb_.jumped_back) cb_.jumped_back();
    if (cb_.changed) cb_.changed();
  });
}

void InputStream::on_vector(const sensor_msgs::MagneticField::ConstPtr& m) {
  guarded("magcomp input", &callback_errors_, [&] {
    Eigen::Vector3d b(m->magnetic_field.x, m->magnetic_field.y, m->magnetic_field.z);
    // A fluxgate mounted with a rotation: into base_frame (its mount is static: looked up once;
    // until it is known the vector is used as it is, and counted).
    const std::string& frame = m->header.frame_id;
    if (!frame.empty() && frame != base_frame_) {
      if (!rotation_known_ || frame != vector_frame_) {
        const double now = ros::WallTime::now().toSec();
        if (now - last_tf_try_wall_s_ > kMountRetryPeriod_s) {
          last_tf_try_wall_s_ = now;
          try {
            const auto tf = tf_buffer_->lookupTransform(base_frame_, frame, ros::Time(0));
            const auto& q = tf.transform.rotation;
            vector_rotation_ = Eigen::Quaterniond(q.w, q.x, q.y, q.z).toRotationMatrix();
            vector_frame_ = frame;
            rotation_known_ = true;
          } catch (const tf2::TransformException& e) {
            ROS_WARN_THROTTLE(kMountWarningPeriod_s,
                              "magcomp: no tf2 %s <- %s yet (%s): fluxgate used as is",
                              base_frame_.c_str(), frame.c_str(), e.what());
          }
        }
      }
      if (rotation_known_ && frame == vector_frame_) {
        b = vector_rotation_ * b;
      } else {
        ++n_no_tf_;
      }
    }
    if (aligner_.add_vector(rel(m->header.stamp), b * kNanoteslaPerTesla) && cb_.changed) {
      cb_.changed();
    }
  });
}

void InputStream::on_aux(const magcomp::AuxChannels::ConstPtr& m) {
  guarded("magcomp input", &callback_errors_, [&] {
    if (m->values.size() != m->names.size()) {
      ROS_WARN_THROTTLE(kMountWarningPeriod_s,
                        "magcomp: an AuxChannels message has %zu names and %zu values: dropped",
                        m->names.size(), m->values.size());
    }
    if (aligner_.add_aux(rel(m->header.stamp), m->names, m->values) && cb_.changed) cb_.changed();
  });
}

void InputStream::on_fix(const sensor_msgs::NavSatFix::ConstPtr& m) {
  guarded("magcomp input", &callback_errors_, [&] {
    if (aligner_.add_fix(rel(m->header.stamp),
                         Eigen::Vector3d(m->latitude, m->longitude, m->altitude)) &&
        cb_.changed) {
      cb_.changed();
    }
  });
}

void InputStream::on_reference(const magcomp::ScalarMagnetometer::ConstPtr& m) {
  guarded("magcomp input", &callback_errors_,
          [&] { aligner_.add_reference(rel(m->header.stamp), m->field_nT); });
}

void InputStream::on_end(const std_msgs::Time::ConstPtr& m) {
  guarded("magcomp input", &callback_errors_, [&] {
    if (cb_.ended) cb_.ended(m->data.toSec());
  });
}

}  // namespace magcomp::rosio
