// magcomp ROS layer: the navigator: INS + compensated anomaly -> map-matching EKF -> map frame.
#include "magcomp/ros/navigator_ros.h"

#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <magcomp/NavigationStatus.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nav_msgs/Odometry.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "held_samples.h"
#include "magcomp/core/error.h"
#include "magcomp/core/geo/attitude.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/online_calibration.h"
#include "magcomp/ros/callback_guard.h"
#include "magcomp/ros/params.h"

namespace magcomp::rosio {
namespace {

const std::set<std::string> kNavigatorParams = {"map_path",
                                                "map_interpolation",
                                                "map_representation_error",
                                                "map_altitude_m",
                                                "anomaly_topic",
                                                "ins_fix_topic",
                                                "imu_topic",
                                                "truth_fix_topic",
                                                "end_of_stream_topic",
                                                "rate_hz",
                                                "measurement_sigma_nT",
                                                "use_compensator_variance",
                                                "map_sigma_nT",
                                                "fogm_sigma_nT",
                                                "fogm_tau_s",
                                                "init_pos_sigma_m",
                                                "init_vel_sigma_mps",
                                                "nis_gate",
                                                "map_frame",
                                                "base_frame",
                                                "origin_lat_deg",
                                                "origin_lon_deg",
                                                "origin_alt_m",
                                                "max_wait_s",
                                                "jump_back_s",
                                                "publish_tf",
                                                "path_stride",
                                                "map_offset_from_first",
                                                "queue_size",
                                                "online",
                                                "model_path",
                                                "prior_path",
                                                "online_cold",
                                                "coefficient_walk",
                                                "columns_topic",
                                                "learned_model_path",
                                                "particles",
                                                "handover_sigma_m"};

constexpr double kNavigatorTimerPeriod_s = 0.1;
constexpr double kNavigatorDiagnosticsPeriod_s = 1.0;
constexpr int kNavigatorOutputQueue = 10000;

double getd(const ros::NodeHandle& pnh, const std::string& key, double def) {
  double v = def;
  pnh.param(key, v, def);
  return v;
}

}  // namespace

NavigatorRos::NavigatorRos(ros::NodeHandle nh, ros::NodeHandle pnh)
    : nh_(nh), pnh_(pnh), updater_(nh, pnh) {
  warn_unknown_params(pnh_, kNavigatorParams);
  pnh_.param<std::string>("map_path", map_path_, "");
  if (map_path_.empty())
    reject_param("map_path", "required (an anomaly map HDF5: map, xx, yy, alt, as MagNav.jl)");
  map_ = nav::read_anomaly_map(map_path_);  // throws naming the file and field
  std::string interp = "linear";
  pnh_.param<std::string>("map_interpolation", interp, "linear");
  if (interp != "linear" && interp != "cubic")
    reject_param("map_interpolation", "must be linear or cubic, got '" + interp + "'");
  if (interp == "cubic") map_.interpolation = nav::AnomalyMap::Interpolation::Cubic;
  pnh_.param("map_representation_error", sigmas_.map_representation_var, true);
  const double map_alt = getd(pnh_, "map_altitude_m", NAN);
  if (std::isfinite(map_alt)) {
    if (map_alt < map_.alt_m - 1.0)
      reject_param("map_altitude_m", "below the map's own altitude (" + std::to_string(map_.alt_m) +
                                         " m): downward continuation is not done");
    if (map_alt > map_.alt_m + 1.0) map_ = nav::continued_to(map_, map_alt);
  }
  const double rate = getd(pnh_, "rate_hz", 10.0);
  require_positive(rate, "rate_hz");
  dt_s_ = 1.0 / rate;
  nav::ModelSigmas& sig = sigmas_;
  // The filter's settings within the ranges that keep it finite (nav_model.h).
  const auto setting = [&](const std::string& key, double def, double hi, const char* unit,
                           bool zero_ok = false) {
    const double v = getd(pnh_, key, def);
    try {
      nav::require_setting(v, 0, hi, "~" + key, unit, zero_ok);
    } catch (const Error& e) {
      reject_param(key, e.what());
    }
    return v;
  };
  const double meas_sigma = setting("measurement_sigma_nT", 3.0, nav::kMaxSigma_nT, "nT");
  sig.meas_var_nT2 = meas_sigma * meas_sigma;
  pnh_.param("use_compensator_variance", use_compensator_variance_, false);
  map_sigma_nT_ = setting("map_sigma_nT", map_.error_sigma_nT, nav::kMaxSigma_nT, "nT", true);
  sig.fogm_nT = setting("fogm_sigma_nT", 3.0, nav::kMaxSigma_nT, "nT");
  sig.taus.fogm_s = setting("fogm_tau_s", 600.0, nav::kMaxTimeConstant_s, "s");
  sig.init_pos_m = setting("init_pos_sigma_m", 3.0, nav::kMaxPositionSigma_m, "m");
  sig.init_vel_mps = setting("init_vel_sigma_mps", 0.01, nav::kMaxVelocitySigma_mps, "m/s");
  const double gate = getd(pnh_, "nis_gate", 0.0);
  if (!(gate >= 0)) reject_param("nis_gate", "must be >= 0 (0: no gate)");
  max_wait_s_ = getd(pnh_, "max_wait_s", 2.0);
  require_positive(max_wait_s_, "max_wait_s");
  jump_back_s_ = getd(pnh_, "jump_back_s", 1.0);
  require_positive(jump_back_s_, "jump_back_s");
  pnh_.param("path_stride", path_stride_, 10);
  if (path_stride_ < 1) reject_param("path_stride", "must be >= 1 (steps per path point)");
  pnh_.param<std::string>("map_frame", map_frame_, "map");
  pnh_.param<std::string>("base_frame", base_frame_, "base_link");
  pnh_.param("publish_tf", publish_tf_, false);
  int queue = 1000;
  pnh_.param("queue_size", queue, 1000);
  if (queue < 1) reject_param("queue_size", "must be >= 1");
  // The map frame: ENU about the origin (default: the map's centre at the map's altitude, so z
  // is the height above the survey altitude and a top-down view holds the tracks).
  const Eigen::Index ny = map_.lat_rad.size(), nx = map_.lon_rad.size();
  const double lat0 =
      getd(pnh_, "origin_lat_deg", 0.5 * (map_.lat_rad[0] + map_.lat_rad[ny - 1]) * kRadToDeg);
  const double lon0 =
      getd(pnh_, "origin_lon_deg", 0.5 * (map_.lon_rad[0] + map_.lon_rad[nx - 1]) * kRadToDeg);
  const double alt0 = getd(pnh_, "origin_alt_m", map_.alt_m);
  if (!(std::abs(lat0) <= 90) || !(std::abs(lon0) <= 360) || !std::isfinite(alt0))
    reject_param("origin_lat_deg", "the map frame's origin must be a valid latitude/longitude");
  enu_ = std::make_unique<LocalEnu>(lat0, lon0, alt0);

  nis_gate_ = gate > 0 ? gate : INFINITY;
  // A start far from the truth: a particle filter first (particle_filter.h).
  int particles = 20000;
  pnh_.param("particles", particles, 20000);
  if (particles != 0 && (particles < 10 || particles > 1000000))
    reject_param("particles", "must be 0 (none) or in 10..1000000");
  const double handover = setting("handover_sigma_m", 30.0, nav::kMaxPositionSigma_m, "m");
  if (sig.init_pos_m > 100.0 && particles > 0) {
    nav::ParticleSettings ps;
    ps.particles = particles;
    ps.init_sigma_m = sig.init_pos_m;
    ps.handover_sigma_m = handover;
    cold_start_ = ps;
  }
  // Online calibration: the compensation model's coefficients learned in the filter.
  pnh_.param("online", online_, false);
  std::string columns_topic;
  pnh_.param<std::string>("columns_topic", columns_topic, "magcomp/compensated/columns");
  pnh_.param<std::string>("learned_model_path", learned_model_path_, "");
  if (online_) {
    std::string model_path, prior_path;
    pnh_.param<std::string>("model_path", model_path, "");
    pnh_.param<std::string>("prior_path", prior_path, "");
    if (model_path.empty())
      reject_param("model_path",
                   "required with ~online (the model whose coefficients are learned)");
    model_ = std::make_unique<Model>(load_model_yaml(model_path));
    prior_ = std::make_unique<Model>(prior_path.empty() ? *model_ : load_model_yaml(prior_path));
    pnh_.param("online_cold", prior_settings_.cold, false);
    prior_settings_.walk_share_per_sqrt_h = getd(pnh_, "coefficient_walk", 0.0);
    if (!(prior_settings_.walk_share_per_sqrt_h >= 0) ||
        !std::isfinite(prior_settings_.walk_share_per_sqrt_h))
      reject_param("coefficient_walk", "must be >= 0 and finite (a share per sqrt(hour))");
    column_names_ = model_->make_column_names();
    nav::FilterSettings probe = nav::filter_model(dt_s_, 0.8, sigmas_);
    try {
      nav::set_coefficient_prior(*model_, prior_.get(), prior_settings_, &probe);
    } catch (const Error& e) {
      reject_param(prior_settings_.cold ? "model_path" : "prior_path", e.what());
    }
  }
  pnh_.param("map_offset_from_first", map_offset_from_first_, true);

  std::string anomaly_topic, fix_topic, imu_topic, truth_topic, end_topic;
  pnh_.param<std::string>("anomaly_topic", anomaly_topic, "magcomp/compensated");
  pnh_.param<std::string>("ins_fix_topic", fix_topic, "magcomp/ins/solution");
  pnh_.param<std::string>("imu_topic", imu_topic, "magcomp/ins/imu");
  pnh_.param<std::string>("truth_fix_topic", truth_topic, "");
  pnh_.param<std::string>("end_of_stream_topic", end_topic, "magcomp/end_of_stream");
  const auto hints = ros::TransportHints().tcpNoDelay();
  sub_anomaly_ = nh_.subscribe(anomaly_topic, static_cast<uint32_t>(queue),
                               &NavigatorRos::on_anomaly, this, hints);
  sub_fix_ = nh_.subscribe(fix_topic, static_cast<uint32_t>(queue), &NavigatorRos::on_ins_fix, this,
                           hints);
  sub_imu_ =
      nh_.subscribe(imu_topic, static_cast<uint32_t>(queue), &NavigatorRos::on_imu, this, hints);
  if (!truth_topic.empty())
    sub_truth_ = nh_.subscribe(truth_topic, static_cast<uint32_t>(queue), &NavigatorRos::on_truth,
                               this, hints);
  if (!end_topic.empty()) sub_end_ = nh_.subscribe(end_topic, 10, &NavigatorRos::on_end, this);
  if (online_) {
    sub_columns_ = nh_.subscribe(columns_topic, static_cast<uint32_t>(queue),
                                 &NavigatorRos::on_columns, this, hints);
    pub_coefficients_ =
        nh_.advertise<magcomp::AuxChannels>("magcomp/nav/coefficients", kNavigatorOutputQueue);
    pub_coefficient_sigma_ =
        nh_.advertise<magcomp::AuxChannels>("magcomp/nav/coefficient_sigma", kNavigatorOutputQueue);
    srv_save_ = pnh_.advertiseService("save_model", &NavigatorRos::on_save_model, this);
  }

  pub_odom_ = nh_.advertise<nav_msgs::Odometry>("magcomp/nav/odometry", kNavigatorOutputQueue);
  pub_pose_ = nh_.advertise<geometry_msgs::PoseWithCovarianceStamped>("magcomp/nav/pose",
                                                                      kNavigatorOutputQueue);
  pub_fix_ = nh_.advertise<sensor_msgs::NavSatFix>("magcomp/nav/fix", kNavigatorOutputQueue);
  pub_status_ =
      nh_.advertise<magcomp::NavigationStatus>("magcomp/nav/status", kNavigatorOutputQueue);
  pub_path_filter_ = nh_.advertise<nav_msgs::Path>("magcomp/nav/path/filter", 1, true);
  pub_path_ins_ = nh_.advertise<nav_msgs::Path>("magcomp/nav/path/ins", 1, true);
  pub_path_truth_ = nh_.advertise<nav_msgs::Path>("magcomp/nav/path/truth", 1, true);
  pub_map_ = nh_.advertise<nav_msgs::OccupancyGrid>("magcomp/nav/map", 1, true);
  publish_map();
  for (nav_msgs::Path* p : {&path_filter_, &path_ins_, &path_truth_})
    p->header.frame_id = map_frame_;
  if (publish_tf_) tf_ = std::make_unique<tf2_ros::TransformBroadcaster>();
  timer_ = nh_.createWallTimer(ros::WallDuration(kNavigatorTimerPeriod_s),
                               [this](const ros::WallTimerEvent&) { on_timer(); });
  updater_.setHardwareID("magcomp navigator: " + map_path_);
  updater_.add("navigator", this, &NavigatorRos::diagnose);
  diag_timer_ =
      nh_.createWallTimer(ros::WallDuration(kNavigatorDiagnosticsPeriod_s),
                          [this](const ros::WallTimerEvent&) { updater_.force_update(); });
  ROS_INFO("magcomp navigator: %s + %s + %s -> magcomp/nav/* in frame %s (map %s, %ldx%ld)",
           anomaly_topic.c_str(), fix_topic.c_str(), imu_topic.c_str(), map_frame_.c_str(),
           map_path_.c_str(), static_cast<long>(ny), static_cast<long>(nx));
}

bool NavigatorRos::jumped_back(double t, double* last) {
  if (std::isfinite(*last) && t < *last - jump_back_s_) {
    ++jumps_back_;
    ROS_WARN("magcomp navigator: time jumped back %.3f s: the filter restarts", *last - t);
    nav_.reset();  // made again at the next INS sample
    ins_pairs_.clear();
    orientations_.clear();
    truth_.clear();
    early_.clear();
    online_pairs_.clear();
    for (nav_msgs::Path* p : {&path_filter_, &path_ins_, &path_truth_}) p->poses.clear();
    truth_seen_ = 0;
    last_anomaly_t_ = last_fix_t_ = last_imu_t_ = NAN;
    *last = t;
    return true;
  }
  *last = std::isfinite(*last) ? std::max(*last, t) : t;
  return false;
}

// Every callback runs guarded (callback_guard.h) and refuses a stamp ROS time cannot carry back
// out (counted): the node survives any message.
bool NavigatorRos::refuse_stamp(const ros::Time& stamp) {
  if (usable_stamp(stamp)) return false;
  ++bad_stamps_;
  return true;
}

void NavigatorRos::on_anomaly(const magcomp::CompensatedField::ConstPtr& m) {
  guarded("magcomp navigator", &callback_errors_, [&] { take_anomaly(*m); });
}

void NavigatorRos::on_ins_fix(const sensor_msgs::NavSatFix::ConstPtr& m) {
  guarded("magcomp navigator", &callback_errors_, [&] { take_ins_fix(*m); });
}

void NavigatorRos::on_imu(const sensor_msgs::Imu::ConstPtr& m) {
  guarded("magcomp navigator", &callback_errors_, [&] { take_imu(*m); });
}

void NavigatorRos::on_truth(const sensor_msgs::NavSatFix::ConstPtr& m) {
  guarded("magcomp navigator", &callback_errors_, [&] { take_truth(*m); });
}

void NavigatorRos::take_anomaly(const magcomp::CompensatedField& msg) {
  const magcomp::CompensatedField* m = &msg;
  if (refuse_stamp(m->header.stamp)) return;
  const double t = m->header.stamp.toSec();
  last_input_wall_s_ = ros::WallTime::now().toSec();
  jumped_back(t, &last_anomaly_t_);
  double var = NAN;
  if (use_compensator_variance_ && std::isfinite(m->variance_nT2))
    var = m->variance_nT2 + map_sigma_nT_ * map_sigma_nT_;
  if (!std::isfinite(m->anomaly_nT)) ++nan_inputs_;  // stepped without it
  if (!online_) {
    feed_measurement(t, {m->anomaly_nT, var, {}});
    return;
  }
  // Online: the raw anomaly (the compensator's anomaly with its aircraft field put back), paired
  // with the model's columns of the same stamp.
  if (auto pair = online_pairs_.add_first(t, {m->anomaly_nT + m->aircraft_correction_nT, var}))
    take_online(*pair);
}

void NavigatorRos::on_columns(const magcomp::AuxChannels::ConstPtr& m) {
  guarded("magcomp navigator", &callback_errors_, [&] {
    if (refuse_stamp(m->header.stamp)) return;
    if (m->names != column_names_ || m->values.size() != column_names_.size()) {
      ++columns_mismatched_;  // another model's columns: they cannot be learned here
      return;
    }
    const double t = m->header.stamp.toSec();
    const Eigen::VectorXd columns = Eigen::Map<const Eigen::VectorXd>(
        m->values.data(), static_cast<Eigen::Index>(m->values.size()));
    if (auto pair = online_pairs_.add_second(t, columns)) take_online(*pair);
  });
}

void NavigatorRos::take_online(const OnlinePairs::Pair& pair) {
  feed_measurement(pair.t_s, {pair.first.z_nT, pair.first.var_nT2, pair.second});
}

void NavigatorRos::feed_measurement(double t, const EarlyMeasurement& m) {
  if (nav_) {
    publish(nav_->push_measurement(t, m.z_nT, m.var_nT2, m.columns.size() ? &m.columns : nullptr));
  } else if (early_.size() < kMaxHeld) {
    early_[t] = m;
  }
}

bool NavigatorRos::on_save_model(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  res.success = false;
  if (learned_model_path_.empty()) {
    res.message = "~learned_model_path is not set: nowhere to write the learned model";
  } else if (!nav_ || !last_ || last_->coefficients.size() == 0) {
    res.message = "nothing learned yet (no filter step)";
  } else {
    try {
      save_model_yaml(
          nav::learned_model(*model_, last_->coefficients, nav_->coefficient_covariance()),
          learned_model_path_);
      res.success = true;
      res.message = "wrote " + learned_model_path_;
    } catch (const std::exception& e) {
      res.message = e.what();
    }
  }
  return true;
}

void NavigatorRos::take_ins_fix(const sensor_msgs::NavSatFix& msg) {
  const sensor_msgs::NavSatFix* m = &msg;
  if (refuse_stamp(m->header.stamp)) return;
  const double t = m->header.stamp.toSec();
  last_input_wall_s_ = ros::WallTime::now().toSec();
  jumped_back(t, &last_fix_t_);
  if (m->status.status < sensor_msgs::NavSatStatus::STATUS_FIX) {
    ++ins_no_fix_;  // the INS says it has no position: not a sample
    return;
  }
  if (!std::isfinite(m->latitude) || !std::isfinite(m->longitude) || !std::isfinite(m->altitude)) {
    ++nan_inputs_;
    return;
  }
  if (auto pair = ins_pairs_.add_first(t, {m->latitude, m->longitude, m->altitude}))
    take_ins(*pair);
}

void NavigatorRos::take_imu(const sensor_msgs::Imu& msg) {
  const sensor_msgs::Imu* m = &msg;
  if (refuse_stamp(m->header.stamp)) return;
  const double t = m->header.stamp.toSec();
  last_input_wall_s_ = ros::WallTime::now().toSec();
  jumped_back(t, &last_imu_t_);
  const Eigen::Quaterniond q(m->orientation.w, m->orientation.x, m->orientation.y,
                             m->orientation.z);
  if (!q.coeffs().allFinite() || std::abs(q.norm() - 1.0) > 1e-3) {
    ++nan_inputs_;
    return;
  }
  if (auto pair = ins_pairs_.add_second(t, {ned_attitude(q.normalized()), q.normalized()}))
    take_ins(*pair);
}

void NavigatorRos::take_truth(const sensor_msgs::NavSatFix& msg) {
  const sensor_msgs::NavSatFix* m = &msg;
  if (refuse_stamp(m->header.stamp)) return;
  const double t = m->header.stamp.toSec();
  if (!(std::abs(m->latitude) <= 90 && std::abs(m->longitude) <= 720 &&
        std::isfinite(m->altitude))) {
    ++nan_inputs_;  // a reference fix the errors cannot be measured against
    return;
  }
  truth_[t] = {m->latitude, m->longitude};
  if (truth_seen_++ % path_stride_ == 0) {
    geometry_msgs::PoseStamped p;
    p.header.stamp = m->header.stamp;
    p.header.frame_id = map_frame_;
    const Eigen::Vector3d e = enu_->forward(m->latitude, m->longitude, m->altitude);
    p.pose.position.x = e.x();
    p.pose.position.y = e.y();
    p.pose.position.z = e.z();
    p.pose.orientation.w = 1.0;
    path_truth_.poses.push_back(p);
  }
}

void NavigatorRos::take_ins(const InsPairs::Pair& pair) {
  const double t = pair.t_s;
  nav::InsSample s;
  s.t_s = t;
  s.lat_rad = pair.first.x() * kDegToRad;
  s.lon_rad = pair.first.y() * kDegToRad;
  s.alt_m = pair.first.z();
  s.roll_rad = pair.second.rpy_rad.x();
  s.pitch_rad = pair.second.rpy_rad.y();
  s.yaw_rad = pair.second.rpy_rad.z();
  if (!nav::invalid_ins_reason(s).empty()) {  // a pole, an altitude off the Earth: refused
    ++ins_refused_;
    return;
  }
  orientations_[t] = pair.second.q_enu_flu;  // the step's output is published with it
  if (!nav_) {
    nav::FilterSettings fs = nav::filter_model(dt_s_, s.lat_rad, sigmas_);
    if (online_) nav::set_coefficient_prior(*model_, prior_.get(), prior_settings_, &fs);
    fs.nis_gate = nis_gate_;
    fs.offset_from_first = map_offset_from_first_;
    nav_ = std::make_unique<nav::StreamingNavigator>(map_, fs, dt_s_,
                                                     cold_start_ ? &*cold_start_ : nullptr);
    publish(nav_->push_ins(s));
    for (const auto& [te, z] : early_)
      publish(
          nav_->push_measurement(te, z.z_nT, z.var_nT2, z.columns.size() ? &z.columns : nullptr));
    early_.clear();
    return;
  }
  publish(nav_->push_ins(s));
}

void NavigatorRos::on_end(const std_msgs::Time::ConstPtr&) {
  guarded("magcomp navigator", &callback_errors_, [&] {
    ROS_INFO("magcomp navigator: end of stream");
    if (nav_) publish(nav_->end_of_ins());
  });
}

}  // namespace magcomp::rosio
