// magcomp ROS layer: topics into the stream aligner.
#include "magcomp/ros/input_stream.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "magcomp/ros/callback_guard.h"
#include "magcomp/ros/params.h"

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

InputParams read_input_params(const ros::NodeHandle& pnh, const std::string& scalar,
                              const std::string& vector) {
  InputParams p;
  AlignerSettings& a = p.aligner;
  pnh.param("max_gap_s", a.max_gap_s, a.max_gap_s);
  pnh.param("max_wait_s", a.max_wait_s, a.max_wait_s);
  pnh.param("jump_back_s", a.jump_back_s, a.jump_back_s);
  pnh.param("buffer_s", a.buffer_s, a.buffer_s);
  require_positive(a.max_gap_s, "max_gap_s");
  require_positive(a.max_wait_s, "max_wait_s");
  require_positive(a.jump_back_s, "jump_back_s");
  require_positive(a.buffer_s, "buffer_s");
  pnh.param("queue_size", p.queue_size, p.queue_size);
  if (p.queue_size < 1)
    reject_param("queue_size", "must be >= 1, got " + std::to_string(p.queue_size));
  pnh.param("tcp_nodelay", p.tcp_nodelay, p.tcp_nodelay);
  pnh.param<std::string>("base_frame", p.base_frame, p.base_frame);
  // Topics are relative by default: a namespaced launch moves them all (magcomp convert's bags,
  // played in the root namespace, use these names).
  InputStream::Topics& t = p.topics;
  pnh.param<std::string>("scalar_topic", t.scalar, "magcomp/scalar/" + scalar);
  pnh.param<std::string>("vector_topic", t.vector, "magcomp/fluxgate/" + vector);
  pnh.param<std::string>("aux_topic", t.aux, "magcomp/aux");
  pnh.param<std::string>("fix_topic", t.fix, "magcomp/ins/fix");
  pnh.param<std::string>("reference_topic", t.reference, "");
  pnh.param<std::string>("end_of_stream_topic", t.end_of_stream, "magcomp/end_of_stream");
  return p;
}

std::set<std::string> with_input_params(std::set<std::string> own) {
  own.insert({"max_gap_s", "max_wait_s", "jump_back_s", "buffer_s", "queue_size", "tcp_nodelay",
              "base_frame", "scalar_topic", "vector_topic", "aux_topic", "fix_topic",
              "reference_topic", "end_of_stream_topic"});
  return own;
}

}  // namespace magcomp::rosio
