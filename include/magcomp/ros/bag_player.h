// magcomp ROS layer: a bag player that lives in a nodelet manager (nodelet magcomp/Player).
#pragma once

#include <magcomp/CompensatedField.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/message_instance.h>

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace magcomp::rosio {

/// Plays a bag's messages on their topics, in the bag's time order, from its own thread. Loaded
/// in the same nodelet manager as the compensator nodelet, the sensor messages reach it as shared
/// pointers: no serialisation and no socket (roscpp's intra-process path), which is what lets a
/// whole flight be replayed through the nodes far faster than `rosbag play` over TCP.
/// The magcomp sensor types (ScalarMagnetometer, AuxChannels, MagneticField, NavSatFix, Imu) are
/// published typed; any other topic is published as its serialised bytes.
/// Back-pressure: with ~progress_topic (the compensator's output) the player stays at most
/// ~max_lead_s of data time ahead of the last output, so however fast it plays nothing is dropped
/// by a full subscriber queue. When the bag is played out it publishes std_msgs/Time (the data time
/// of its last message) on ~end_topic: a compensator listening there flushes its last samples at
/// once instead of after a wall-time silence, so a stalled player is never mistaken for the end.
/// Parameters: see config/player.yaml.
class BagPlayer {
 public:
  /// Reads and validates the private parameters, opens the bag (throws magcomp::Error naming the
  /// bag or parameter) and starts playing in a thread.
  BagPlayer(ros::NodeHandle nh, ros::NodeHandle pnh);
  /// Stops playing and joins the thread.
  ~BagPlayer();
  BagPlayer(const BagPlayer&) = delete;
  BagPlayer& operator=(const BagPlayer&) = delete;

 private:
  struct TopicOut {
    std::string topic;
    ros::Publisher pub;
    std::function<void(const rosbag::MessageInstance&)> publish;
  };
  void run();
  void on_progress(const magcomp::CompensatedField::ConstPtr& m);
  /// When data time t_s (s since the epoch) is more than max_lead_s past the last output, blocks
  /// until it is within max_lead_s / 2, the consumer stalls for stall_timeout_s of wall time, or
  /// the player stops. The progress messages are taken from their own queue in the player's
  /// thread: no other thread is woken per output.
  void wait_for_progress(double t_s);

  ros::NodeHandle nh_, pnh_;
  std::string bag_path_;
  std::unique_ptr<rosbag::Bag> bag_;
  std::vector<std::string> topics_;
  double rate_ = 1.0, start_delay_s_ = 0.0, max_lead_s_ = 30.0, stall_timeout_s_ = 5.0;
  bool wait_for_subscribers_ = false, publish_clock_ = false;
  int queue_size_ = 10000;
  ros::CallbackQueue progress_queue_;
  ros::Subscriber sub_progress_;
  ros::Publisher pub_clock_, pub_end_;
  /// One publisher per played topic. Members, so they outlive the playing: a publisher destroyed
  /// when the bag ends would drop the messages still queued for subscribers in other processes.
  std::map<std::string, TopicOut> out_;
  double progress_t_s_ = -1.0;  // stamp of the last output seen (s since the epoch), -1: none yet
  long stalls_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace magcomp::rosio
