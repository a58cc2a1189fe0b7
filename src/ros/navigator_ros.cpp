// magcomp ROS layer: the navigator: INS + compensated anomaly -> map-matching EKF -> map frame.
#include "magcomp/ros/navigator_ros.h"

#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <magcomp/NavigationStatus.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nav_msgs/Odometry.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/online_calibration.h"
#include "magcomp/ros/callback_guard.h"
#include "magcomp/ros/ins_attitude.h"
#include "magcomp/ros/params.h"

namespace magcomp::rosio {
namespace {

const std::set<std::string> kKnownParams = {"map_path",
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

constexpr double kTimerPeriod_s = 0.1;
constexpr double kDiagnosticsPeriod_s = 1.0;
constexpr int kOutputQueue = 10000;
constexpr long kOffMapWarnSteps = 10;  // consecutive steps off the map: a warning
constexpr size_t kMaxHeld = 20000;     // INS halves or reference fixes held, at most

template <class M>
void prune_before(M& m, double t) {
  while (!m.empty() && m.begin()->first < t) m.erase(m.begin());
  while (m.size() > kMaxHeld) m.erase(m.begin());
}

double getd(const ros::NodeHandle& pnh, const std::string& key, double def) {
  double v = def;
  pnh.param(key, v, def);
  return v;
}

}  // namespace

NavigatorRos::NavigatorRos(ros::NodeHandle nh, ros::NodeHandle pnh)
    : nh_(nh), pnh_(pnh), updater_(nh, pnh) {
  warn_unknown_params(pnh_, kKnownParams);
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
        nh_.advertise<magcomp::AuxChannels>("magcomp/nav/coefficients", kOutputQueue);
    pub_coefficient_sigma_ =
        nh_.advertise<magcomp::AuxChannels>("magcomp/nav/coefficient_sigma", kOutputQueue);
    srv_save_ = pnh_.advertiseService("save_model", &NavigatorRos::on_save_model, this);
  }

  pub_odom_ = nh_.advertise<nav_msgs::Odometry>("magcomp/nav/odometry", kOutputQueue);
  pub_pose_ =
      nh_.advertise<geometry_msgs::PoseWithCovarianceStamped>("magcomp/nav/pose", kOutputQueue);
  pub_fix_ = nh_.advertise<sensor_msgs::NavSatFix>("magcomp/nav/fix", kOutputQueue);
  pub_status_ = nh_.advertise<magcomp::NavigationStatus>("magcomp/nav/status", kOutputQueue);
  pub_path_filter_ = nh_.advertise<nav_msgs::Path>("magcomp/nav/path/filter", 1, true);
  pub_path_ins_ = nh_.advertise<nav_msgs::Path>("magcomp/nav/path/ins", 1, true);
  pub_path_truth_ = nh_.advertise<nav_msgs::Path>("magcomp/nav/path/truth", 1, true);
  pub_map_ = nh_.advertise<nav_msgs::OccupancyGrid>("magcomp/nav/map", 1, true);
  publish_map();
  for (nav_msgs::Path* p : {&path_filter_, &path_ins_, &path_truth_})
    p->header.frame_id = map_frame_;
  if (publish_tf_) tf_ = std::make_unique<tf2_ros::TransformBroadcaster>();
  timer_ = nh_.createWallTimer(ros::WallDuration(kTimerPeriod_s),
                               [this](const ros::WallTimerEvent&) { on_timer(); });
  updater_.setHardwareID("magcomp navigator: " + map_path_);
  updater_.add("navigator", this, &NavigatorRos::diagnose);
  diag_timer_ =
      nh_.createWallTimer(ros::WallDuration(kDiagnosticsPeriod_s),
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
    fixes_.clear();
    attitudes_.clear();
    orientations_.clear();
    truth_.clear();
    early_.clear();
    online_parts_.clear();
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
  OnlinePart& part = online_parts_[t];
  part.z_nT = m->anomaly_nT + m->aircraft_correction_nT;
  part.var_nT2 = var;
  part.has_z = true;
  try_online(t);
}

void NavigatorRos::on_columns(const magcomp::AuxChannels::ConstPtr& m) {
  guarded("magcomp navigator", &callback_errors_, [&] {
    if (refuse_stamp(m->header.stamp)) return;
    if (m->names != column_names_ || m->values.size() != column_names_.size()) {
      ++columns_mismatched_;  // another model's columns: they cannot be learned here
      return;
    }
    const double t = m->header.stamp.toSec();
    OnlinePart& part = online_parts_[t];
    part.columns = Eigen::Map<const Eigen::VectorXd>(m->values.data(),
                                                     static_cast<Eigen::Index>(m->values.size()));
    try_online(t);
  });
}

void NavigatorRos::try_online(double t) {
  auto it = online_parts_.find(t);
  if (it == online_parts_.end() || !it->second.has_z || it->second.columns.size() == 0) {
    prune_before(online_parts_, t - 10.0);  // a half older than 10 s never finds its pair
    return;
  }
  feed_measurement(t, {it->second.z_nT, it->second.var_nT2, it->second.columns});
  online_parts_.erase(it);
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
  fixes_[t] = {m->latitude, m->longitude, m->altitude};
  try_ins(t);
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
  attitudes_[t] = ned_attitude(q.normalized());
  orientations_[t] = q.normalized();
  try_ins(t);
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

void NavigatorRos::try_ins(double t) {
  auto f = fixes_.find(t);
  auto a = attitudes_.find(t);
  if (f == fixes_.end() || a == attitudes_.end()) return;
  nav::InsSample s;
  s.t_s = t;
  s.lat_rad = f->second.x() * kDegToRad;
  s.lon_rad = f->second.y() * kDegToRad;
  s.alt_m = f->second.z();
  s.roll_rad = a->second.x();
  s.pitch_rad = a->second.y();
  s.yaw_rad = a->second.z();
  if (!nav::invalid_ins_reason(s).empty()) {  // a pole, an altitude off the Earth: refused
    ++ins_refused_;
    fixes_.erase(t);
    attitudes_.erase(t);
    return;
  }
  // Halves older than this sample never found their pair.
  for (auto it = attitudes_.begin(); it != attitudes_.end() && it->first < t;)
    it = attitudes_.erase(it), ++imu_without_fix_dropped_;
  prune_before(fixes_, t);
  fixes_.erase(t);
  attitudes_.erase(t);
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

void NavigatorRos::publish_map() {
  // The anomaly map for rviz: an OccupancyGrid in the map frame (its cells 0-100 spanning the
  // map's range; the grid's lat/lon axes laid on east/north at its corner, to a few metres
  // over a survey block).
  nav_msgs::OccupancyGrid g;
  g.header.frame_id = map_frame_;
  g.header.stamp = ros::Time(0);
  const Eigen::Index ny = map_.map_nT.rows(), nx = map_.map_nT.cols();
  const Eigen::Vector2d step = map_.step_m();
  g.info.resolution = static_cast<float>(0.5 * (step.x() + step.y()));
  g.info.width = static_cast<uint32_t>(nx);
  g.info.height = static_cast<uint32_t>(ny);
  const Eigen::Vector3d corner =
      enu_->forward(map_.lat_rad[0] * kRadToDeg, map_.lon_rad[0] * kRadToDeg, map_.alt_m);
  g.info.origin.position.x = corner.x();
  g.info.origin.position.y = corner.y();
  g.info.origin.position.z = corner.z();
  g.info.origin.orientation.w = 1.0;
  const double lo = map_.map_nT.minCoeff(), hi = map_.map_nT.maxCoeff();
  g.data.resize(static_cast<size_t>(nx * ny));
  for (Eigen::Index r = 0; r < ny; ++r)
    for (Eigen::Index c = 0; c < nx; ++c) {
      const bool valid = map_.mask.size() == 0 || map_.mask(r, c) != 0;
      g.data[static_cast<size_t>(r * nx + c)] = static_cast<int8_t>(
          valid && hi > lo ? std::lround(100.0 * (map_.map_nT(r, c) - lo) / (hi - lo)) : -1);
    }
  pub_map_.publish(g);
}

void NavigatorRos::on_timer() {
  guarded("magcomp navigator", &callback_errors_, [&] {
    // A measurement source silent for max_wait_s (wall): the INS samples waiting go without one.
    if (nav_ && nav_->pending() > 0 &&
        ros::WallTime::now().toSec() - last_input_wall_s_ > max_wait_s_)
      publish(nav_->flush());
  });
}

void NavigatorRos::publish(const std::vector<nav::NavigatorOutput>& steps) {
  for (const nav::NavigatorOutput& o : steps) {
    const ros::Time stamp(o.t_s);
    const double lat_deg = o.lat_rad * kRadToDeg, lon_deg = o.lon_rad * kRadToDeg;
    const Eigen::Vector3d pos = enu_->forward(lat_deg, lon_deg, o.alt_m);
    // Covariance NED -> ENU (x east, y north, z up).
    const Eigen::Matrix3d swap = LocalEnu::ned_to_enu();
    const Eigen::Matrix3d cov = swap * o.position_cov_ned_m2 * swap.transpose();
    const Eigen::Vector3d vel_enu = swap * o.velocity_ned_mps;
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    auto qi = orientations_.find(o.t_s);
    if (qi != orientations_.end()) q = qi->second;
    prune_before(orientations_, o.t_s);

    geometry_msgs::PoseWithCovariance pose;
    pose.pose.position.x = pos.x();
    pose.pose.position.y = pos.y();
    pose.pose.position.z = pos.z();
    pose.pose.orientation.w = q.w();
    pose.pose.orientation.x = q.x();
    pose.pose.orientation.y = q.y();
    pose.pose.orientation.z = q.z();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) pose.covariance[static_cast<size_t>(6 * i + j)] = cov(i, j);
    // The attitude is the INS's: its uncertainty is not estimated here (a large value, so a
    // fusion node takes it from the INS).
    for (int i = 3; i < 6; ++i) pose.covariance[static_cast<size_t>(7 * i)] = 1e3;
    if (pub_odom_.getNumSubscribers() > 0) {
      nav_msgs::Odometry odom;
      odom.header.stamp = stamp;
      odom.header.frame_id = map_frame_;
      odom.child_frame_id = base_frame_;
      odom.pose = pose;
      // The twist is in the child frame (base_link, x forward y left z up).
      const Eigen::Vector3d v_body = q.conjugate() * vel_enu;
      odom.twist.twist.linear.x = v_body.x();
      odom.twist.twist.linear.y = v_body.y();
      odom.twist.twist.linear.z = v_body.z();
      for (int i = 0; i < 6; ++i)
        odom.twist.covariance[static_cast<size_t>(7 * i)] = i < 3 ? 0.01 : 1e3;
      pub_odom_.publish(odom);
    }
    geometry_msgs::PoseWithCovarianceStamped ps;
    ps.header.stamp = stamp;
    ps.header.frame_id = map_frame_;
    ps.pose = pose;
    pub_pose_.publish(ps);
    sensor_msgs::NavSatFix fix;
    fix.header.stamp = stamp;
    fix.header.frame_id = base_frame_;
    fix.status.status = o.step.on_map ? sensor_msgs::NavSatStatus::STATUS_FIX
                                      : sensor_msgs::NavSatStatus::STATUS_NO_FIX;
    fix.latitude = lat_deg;
    fix.longitude = lon_deg;
    fix.altitude = o.alt_m;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        fix.position_covariance[static_cast<size_t>(3 * i + j)] = cov(i, j);
    fix.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_KNOWN;
    pub_fix_.publish(fix);

    magcomp::NavigationStatus st;
    st.header.stamp = stamp;
    st.header.frame_id = map_frame_;
    st.measurement_nT = o.measurement_nT;
    st.map_nT = o.map_nT;
    st.catch_all_nT = o.catch_all_nT;
    st.innovation_nT = o.step.innovation_nT;
    st.innovation_sigma_nT = std::sqrt(o.step.innovation_var_nT2);
    st.nis = o.step.innovation_nT * o.step.innovation_nT / o.step.innovation_var_nT2;
    st.measurement_sigma_nT = std::sqrt(o.measurement_var_nT2);
    st.measurement_used = o.step.updated;
    st.on_map = o.step.on_map;
    st.sigma_north_m = std::sqrt(o.position_cov_ned_m2(0, 0));
    st.sigma_east_m = std::sqrt(o.position_cov_ned_m2(1, 1));
    st.correction_north_m = nav::dlat_to_north_m(o.lat_rad - o.ins_lat_rad, o.lat_rad);
    st.correction_east_m = nav::dlon_to_east_m(o.lon_rad - o.ins_lon_rad, o.lat_rad);
    st.error_north_m = st.error_east_m = st.error_horizontal_m = st.ins_error_horizontal_m = NAN;
    auto tr = truth_.find(o.t_s);
    if (tr != truth_.end()) {
      const double tl = tr->second.x() * kDegToRad, tn = tr->second.y() * kDegToRad;
      st.error_north_m = nav::dlat_to_north_m(o.lat_rad - tl, tl);
      st.error_east_m = nav::dlon_to_east_m(o.lon_rad - tn, tl);
      st.error_horizontal_m = std::hypot(st.error_north_m, st.error_east_m);
      st.ins_error_horizontal_m = std::hypot(nav::dlat_to_north_m(o.ins_lat_rad - tl, tl),
                                             nav::dlon_to_east_m(o.ins_lon_rad - tn, tl));
    }
    prune_before(truth_, o.t_s);
    pub_status_.publish(st);
    if (online_ && o.coefficients.size() > 0) {  // what the filter has learned, plain numbers
      for (auto [pub, v] : {std::pair{&pub_coefficients_, &o.coefficients},
                            std::pair{&pub_coefficient_sigma_, &o.coefficient_sigma}}) {
        if (pub->getNumSubscribers() == 0) continue;
        magcomp::AuxChannels c;
        c.header.stamp = stamp;
        c.header.frame_id = map_frame_;
        c.names = column_names_;
        c.values.assign(v->data(), v->data() + v->size());
        pub->publish(c);
      }
    }
    if (std::isfinite(st.nis) && o.step.updated) {
      nis_sum_ += st.nis;
      ++nis_n_;
    }
    consecutive_off_map_ = o.step.on_map ? 0 : consecutive_off_map_ + 1;

    if (tf_) {
      geometry_msgs::TransformStamped tf;
      tf.header.stamp = stamp;
      tf.header.frame_id = map_frame_;
      tf.child_frame_id = base_frame_;
      tf.transform.translation.x = pos.x();
      tf.transform.translation.y = pos.y();
      tf.transform.translation.z = pos.z();
      tf.transform.rotation = pose.pose.orientation;
      tf_->sendTransform(tf);
    }
    if (published_ % path_stride_ == 0) {
      geometry_msgs::PoseStamped p;
      p.header = ps.header;
      p.pose = pose.pose;
      path_filter_.poses.push_back(p);
      const Eigen::Vector3d ins =
          enu_->forward(o.ins_lat_rad * kRadToDeg, o.ins_lon_rad * kRadToDeg, o.ins_alt_m);
      p.pose.position.x = ins.x();
      p.pose.position.y = ins.y();
      p.pose.position.z = ins.z();
      path_ins_.poses.push_back(p);
      if (path_filter_.poses.size() % 20 == 0) {
        for (auto pair : {std::make_pair(&path_filter_, &pub_path_filter_),
                          std::make_pair(&path_ins_, &pub_path_ins_),
                          std::make_pair(&path_truth_, &pub_path_truth_)}) {
          pair.first->header.stamp = stamp;
          pair.second->publish(*pair.first);
        }
      }
    }
    ++published_;
    last_ = o;
  }
}

void NavigatorRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  const nav::NavigatorCounts c = nav_ ? nav_->counts() : nav::NavigatorCounts{};
  if (consecutive_off_map_ >= kOffMapWarnSteps) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                 "off the map: navigating on the INS alone");
  } else if (callback_errors_ > 0) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR,
                 "messages dropped on an internal error (see callback_errors)");
  } else if (c.gaps + c.out_of_order + jumps_back_ + nan_inputs_ + c.missing_measurements +
                 c.invalid_ins + c.invalid_measurements + c.filter_restarts + c.ins_jumps +
                 bad_stamps_ + ins_no_fix_ + ins_refused_ >
             0) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                 "running; input faults seen (see counts)");
  } else {
    stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "running");
  }
  stat.add("map_path", map_path_);
  stat.add("ins_samples_in", c.ins_in);
  stat.add("measurements_in", c.measurements_in);
  stat.add("steps", c.steps);
  stat.add("published", published_);
  stat.add("updates", c.updates);
  stat.add("missing_measurements", c.missing_measurements);
  stat.add("unmatched_measurements_dropped", c.unmatched_measurements);
  stat.add("off_map_measurements", c.off_map);
  stat.add("gated_measurements", c.gated);
  stat.add("nan_measurements", c.nan_measurements);
  stat.add("ins_gaps", c.gaps);
  stat.add("out_of_order_dropped", c.out_of_order);
  stat.add("time_jumps_back", jumps_back_);
  stat.add("nan_inputs", nan_inputs_);
  stat.add("imu_without_fix_dropped", imu_without_fix_dropped_);
  stat.add("ins_no_fix_dropped", ins_no_fix_);
  stat.add("ins_refused", ins_refused_ + c.invalid_ins);
  stat.add("measurements_refused", c.invalid_measurements);
  stat.add("filter_restarts", c.filter_restarts);
  stat.add("ins_jumps", c.ins_jumps);
  stat.add("stamps_out_of_range", bad_stamps_);
  stat.add("callback_errors", callback_errors_);
  if (cold_start_) {
    stat.add("cold_start_particle_steps", c.particle_steps);
    stat.add("cold_start_handed_over", nav_ && !nav_->in_cold_start());
  }
  if (online_) {
    stat.add("online_columns_mismatched", columns_mismatched_);
    stat.add("online_halves_waiting", static_cast<long>(online_parts_.size()));
  }
  stat.add("pending", nav_ ? static_cast<long>(nav_->pending()) : 0L);
  if (nis_n_ > 0) stat.add("nis_mean", nis_sum_ / static_cast<double>(nis_n_));
  stat.add("on_map", last_ ? last_->step.on_map : false);
  if (last_) {
    stat.add("last_innovation_nT", last_->step.innovation_nT);
    stat.add("sigma_horizontal_m",
             std::sqrt(last_->position_cov_ned_m2(0, 0) + last_->position_cov_ned_m2(1, 1)));
  }
}

}  // namespace magcomp::rosio
