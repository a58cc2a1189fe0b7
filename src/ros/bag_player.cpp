// magcomp ROS layer: the in-manager bag player (zero-copy replay into the compensator nodelet).
#include "magcomp/ros/bag_player.h"

#include <magcomp/AuxChannels.h>
#include <magcomp/ScalarMagnetometer.h>
#include <rosbag/view.h>
#include <rosgraph_msgs/Clock.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/MagneticField.h>
#include <sensor_msgs/NavSatFix.h>
#include <std_msgs/Time.h>

#include <chrono>
#include <map>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/ros/params.h"

namespace magcomp::rosio {
namespace {

const std::set<std::string> kPlayerParams = {
    "bag",      "topics",         "rate",       "start_delay_s",   "wait_for_subscribers",
    "clock",    "progress_topic", "max_lead_s", "stall_timeout_s", "queue_size",
    "end_topic"};

/// A publisher of M that hands subscribers in this process the instantiated message itself.
template <typename M>
std::function<void(const rosbag::MessageInstance&)> typed_publisher(ros::Publisher pub) {
  return [pub](const rosbag::MessageInstance& m) {
    boost::shared_ptr<M> msg = m.instantiate<M>();
    if (msg) pub.publish(boost::shared_ptr<const M>(std::move(msg)));
  };
}

}  // namespace

BagPlayer::BagPlayer(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh), pnh_(pnh) {
  warn_unknown_params(pnh_, kPlayerParams);
  if (!pnh_.getParam("bag", bag_path_) || bag_path_.empty())
    reject_param("bag", "required (a bag written by magcomp convert, or any bag)");
  pnh_.getParam("topics", topics_);
  // A bag stores resolved (absolute) names: "magcomp/aux" and "/magcomp/aux" select the same.
  for (auto& topic : topics_)
    if (topic.rfind('/', 0) != 0) topic = "/" + topic;
  // Defaults: the members' initialisers in bag_player.h (one place).
  pnh_.param("rate", rate_, rate_);
  pnh_.param("start_delay_s", start_delay_s_, start_delay_s_);
  pnh_.param("wait_for_subscribers", wait_for_subscribers_, wait_for_subscribers_);
  pnh_.param("clock", publish_clock_, publish_clock_);
  pnh_.param("max_lead_s", max_lead_s_, max_lead_s_);
  pnh_.param("stall_timeout_s", stall_timeout_s_, stall_timeout_s_);
  pnh_.param("queue_size", queue_size_, queue_size_);
  std::string progress_topic;
  pnh_.param<std::string>("progress_topic", progress_topic, "");
  if (!(rate_ >= 0)) reject_param("rate", "must be >= 0 (0: as fast as possible)");
  if (!(start_delay_s_ >= 0)) reject_param("start_delay_s", "must be >= 0 s");
  if (!(max_lead_s_ > 0)) reject_param("max_lead_s", "must be > 0 s");
  if (!(stall_timeout_s_ > 0)) reject_param("stall_timeout_s", "must be > 0 s");
  if (queue_size_ < 1) reject_param("queue_size", "must be >= 1");
  try {
    bag_ = std::make_unique<rosbag::Bag>(bag_path_, rosbag::bagmode::Read);
  } catch (const std::exception& e) {
    reject_param("bag", bag_path_ + ": " + e.what());
  }
  if (!progress_topic.empty()) {
    ros::NodeHandle progress_nh(nh_);
    progress_nh.setCallbackQueue(&progress_queue_);
    sub_progress_ = progress_nh.subscribe(progress_topic, 100000, &BagPlayer::on_progress, this,
                                          ros::TransportHints().tcpNoDelay());
  }
  if (publish_clock_) pub_clock_ = nh_.advertise<rosgraph_msgs::Clock>("/clock", 10);
  std::string end_topic;
  pnh_.param<std::string>("end_topic", end_topic, "magcomp/end_of_stream");
  if (!end_topic.empty()) pub_end_ = nh_.advertise<std_msgs::Time>(end_topic, 10, true);
  thread_ = std::thread([this] { run(); });
}

BagPlayer::~BagPlayer() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

void BagPlayer::on_progress(const magcomp::CompensatedField::ConstPtr& m) {
  progress_t_s_ = std::max(progress_t_s_, m->header.stamp.toSec());
}

void BagPlayer::wait_for_progress(double t_s) {
  progress_queue_.callAvailable(ros::WallDuration(0));
  if (progress_t_s_ < 0) progress_t_s_ = t_s;  // nothing out yet: count the lead from here
  if (t_s - progress_t_s_ <= max_lead_s_) return;
  // Too far ahead: wait until the consumer is back within half the lead, looking every
  // millisecond. Waking once per output instead would cost more than the consumer's work.
  double seen = progress_t_s_;
  auto last_change = std::chrono::steady_clock::now();
  while (!stop_ && ros::ok() && t_s - progress_t_s_ > 0.5 * max_lead_s_) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    progress_queue_.callAvailable(ros::WallDuration(0));
    if (progress_t_s_ != seen) {
      seen = progress_t_s_;
      last_change = std::chrono::steady_clock::now();
    } else if (std::chrono::duration<double>(std::chrono::steady_clock::now() - last_change)
                   .count() > stall_timeout_s_) {
      ++stalls_;
      ROS_WARN("magcomp player: no output on %s for %.1f s: playing on without waiting",
               sub_progress_.getTopic().c_str(), stall_timeout_s_);
      progress_t_s_ = t_s;  // start counting the lead again from here
      return;
    }
  }
}

void BagPlayer::run() {
  std::unique_ptr<rosbag::View> view;
  if (topics_.empty()) {
    view = std::make_unique<rosbag::View>(*bag_);
  } else {
    view = std::make_unique<rosbag::View>(*bag_, rosbag::TopicQuery(topics_));
  }
  // One publisher per topic, typed for the types the nodes subscribe to.
  std::map<std::string, TopicOut>& out = out_;
  const auto q = static_cast<uint32_t>(queue_size_);
  for (const rosbag::ConnectionInfo* c : view->getConnections()) {
    if (out.count(c->topic)) continue;
    TopicOut& t = out[c->topic];
    // The bag's names are absolute (/magcomp/...): they are published in the player's namespace,
    // so a player in the root namespace keeps them and one under <group ns="uav1"> moves them.
    t.topic = c->topic.rfind('/', 0) == 0 ? c->topic.substr(1) : c->topic;
    if (c->datatype == "magcomp/ScalarMagnetometer") {
      t.pub = nh_.advertise<magcomp::ScalarMagnetometer>(t.topic, q);
      t.publish = typed_publisher<magcomp::ScalarMagnetometer>(t.pub);
    } else if (c->datatype == "magcomp/AuxChannels") {
      t.pub = nh_.advertise<magcomp::AuxChannels>(t.topic, q);
      t.publish = typed_publisher<magcomp::AuxChannels>(t.pub);
    } else if (c->datatype == "sensor_msgs/MagneticField") {
      t.pub = nh_.advertise<sensor_msgs::MagneticField>(t.topic, q);
      t.publish = typed_publisher<sensor_msgs::MagneticField>(t.pub);
    } else if (c->datatype == "sensor_msgs/NavSatFix") {
      t.pub = nh_.advertise<sensor_msgs::NavSatFix>(t.topic, q);
      t.publish = typed_publisher<sensor_msgs::NavSatFix>(t.pub);
    } else if (c->datatype == "sensor_msgs/Imu") {
      t.pub = nh_.advertise<sensor_msgs::Imu>(t.topic, q);
      t.publish = typed_publisher<sensor_msgs::Imu>(t.pub);
    } else {  // any other type: its serialised bytes, as rosbag play does
      ros::AdvertiseOptions opts(t.topic, q, c->md5sum, c->datatype, c->msg_def);
      t.pub = nh_.advertise(opts);
      ros::Publisher pub = t.pub;
      t.publish = [pub](const rosbag::MessageInstance& m) { pub.publish(m); };
    }
  }
  for (const auto& topic : topics_) {
    if (!out.count(topic))
      ROS_WARN("magcomp player: topic %s is not in %s", topic.c_str(), bag_path_.c_str());
  }
  if (wait_for_subscribers_) {
    auto last_log = std::chrono::steady_clock::now();
    for (;;) {
      std::string waiting;
      for (const auto& [topic, t] : out) {
        if (t.pub.getNumSubscribers() == 0) waiting += " " + topic;
      }
      if (waiting.empty() || stop_ || !ros::ok()) break;
      if (std::chrono::steady_clock::now() - last_log > std::chrono::seconds(5)) {
        ROS_INFO("magcomp player: waiting for subscribers on%s", waiting.c_str());
        last_log = std::chrono::steady_clock::now();
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(start_delay_s_));
  const std::string speed = rate_ > 0 ? std::to_string(rate_) + "x" : "full speed";
  ROS_INFO("magcomp player: playing %s (%u messages, %zu topics) at %s", bag_path_.c_str(),
           view->size(), out.size(), speed.c_str());
  const auto wall0 = std::chrono::steady_clock::now();
  double bag_t0 = -1, last_clock = -1e300;
  long played = 0;
  ros::Time last_stamp;
  for (const rosbag::MessageInstance& m : *view) {
    if (stop_ || !ros::ok()) break;
    const double t = m.getTime().toSec();
    if (bag_t0 < 0) bag_t0 = t;
    if (rate_ > 0) {
      std::this_thread::sleep_until(wall0 +
                                    std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                        std::chrono::duration<double>((t - bag_t0) / rate_)));
    }
    if (sub_progress_) wait_for_progress(t);
    if (publish_clock_ && t - last_clock >= 0.01) {
      rosgraph_msgs::Clock c;
      c.clock = m.getTime();
      pub_clock_.publish(c);
      last_clock = t;
    }
    out.at(m.getTopic()).publish(m);
    last_stamp = m.getTime();
    ++played;
  }
  if (pub_end_ && !stop_ && ros::ok()) {  // latched: a late subscriber still learns of the end
    std_msgs::Time end;
    end.data = last_stamp;
    pub_end_.publish(end);
  }
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  ROS_INFO("magcomp player: played %ld messages in %.3f s (%.0f messages/s); %ld stalls of %s",
           played, wall_s, played / std::max(wall_s, 1e-9), stalls_,
           sub_progress_ ? sub_progress_.getTopic().c_str() : "(no progress topic)");
}

}  // namespace magcomp::rosio
