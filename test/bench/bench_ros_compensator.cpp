// magcomp benchmark: compensator throughput and latency through ROS (run by scripts/bench_ros).
// Publishes a flight's scalar, fluxgate and aux messages as fast as the compensator keeps up, and
// measures: samples per second end to end, and the latency from publishing the message that
// completes an output's window (sample i + lookahead) to receiving output i. Nothing may be lost.
// With ~listen_only:=true it publishes nothing: `rosbag play` of the flight's bag feeds the node
// (the benchmark's own definition: a bag played as fast as possible), and it measures the output
// rate from the first to the last output.
// With ~in_process:=true the compensator is the nodelet magcomp/Compensator loaded in this process
// (as a nodelet manager does), so every message passes as a shared pointer: no serialisation, no
// socket. With both, the nodelet magcomp/Player plays ~bag in this process too.
#include <magcomp/AuxChannels.h>
#include <magcomp/CompensatedField.h>
#include <magcomp/ScalarMagnetometer.h>
#include <nodelet/loader.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <sensor_msgs/MagneticField.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <thread>

#include "magcomp/core/model/model.h"
#include "magcomp/ros/bag_converter.h"

namespace {
std::mutex g_mutex;
std::vector<double> g_recv_wall;  // by sample index
std::atomic<long> g_received{0};
double g_t0_stamp = 0;
}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "bench_compensator");
  ros::NodeHandle nh, pnh("~");
  std::string h5, model_path;
  int lookahead = 6, window = 800;
  pnh.getParam("h5", h5);
  pnh.getParam("model", model_path);
  pnh.param("lookahead", lookahead, 6);
  pnh.param("in_flight", window, 800);  // samples in flight at most (back-pressure, no drops)
  bool all_channels = true;             // false: the aux message carries only the model's channels
  pnh.param("all_channels", all_channels, true);
  bool nodelay = true;  // false: Nagle on the output link too (flood throughput)
  pnh.param("nodelay", nodelay, true);
  double rate_hz = 0.0;  // 0: as fast as possible (throughput); else paced (latency)
  pnh.param("rate_hz", rate_hz, 0.0);
  bool in_process = false;  // true: the compensator (and player) nodelets in this process
  pnh.param("in_process", in_process, false);
  bool listen_only = false;
  pnh.param("listen_only", listen_only, false);
  std::unique_ptr<nodelet::Loader> manager;
  if (in_process) {
    manager = std::make_unique<nodelet::Loader>(false);
    ros::param::set("/magcomp_compensator/model_path", model_path);
    ros::param::set("/magcomp_compensator/expected_rate_hz", 10000.0);
    ros::param::set("/magcomp_compensator/queue_size", 200000);
    if (!manager->load("/magcomp_compensator", "magcomp/Compensator", {}, {})) {
      std::fprintf(stderr, "bench: could not load the nodelet magcomp/Compensator\n");
      return 2;
    }
  }
  const magcomp::FlightData f = magcomp::read_flight_h5(h5);
  const magcomp::Model m = magcomp::load_model_yaml(model_path);
  const Eigen::Index n = f.size();
  g_recv_wall.assign(static_cast<size_t>(n), -1);
  std::vector<double> sent_wall(static_cast<size_t>(n), -1);
  const int year = static_cast<int>(f.column("year")[0]),
            doy = static_cast<int>(f.column("doy")[0]);
  g_t0_stamp = magcomp::rosio::stamp_of(year, doy, f.tt()[0]).toSec();
  auto scalar = nh.advertise<magcomp::ScalarMagnetometer>("/magcomp/scalar/" + m.scalar, 10000);
  auto vec = nh.advertise<sensor_msgs::MagneticField>("/magcomp/fluxgate/" + m.vector, 10000);
  auto aux = nh.advertise<magcomp::AuxChannels>("/magcomp/aux", 10000);
  // The outputs arrive on their own queue. Paced (latency), a spinner thread takes each at once;
  // flooding (throughput), this thread drains them between publishes and while it waits, so the
  // listener does not add a wake-up per output to what is measured.
  ros::CallbackQueue out_queue;
  ros::NodeHandle out_nh;
  out_nh.setCallbackQueue(&out_queue);
  ros::Subscriber sub = out_nh.subscribe<magcomp::CompensatedField>(
      "/magcomp/compensated", 100000,
      [&](const magcomp::CompensatedField::ConstPtr& o) {
        const long i = std::lround((o->header.stamp.toSec() - g_t0_stamp) * 10.0);
        if (i >= 0 && i < n) g_recv_wall[static_cast<size_t>(i)] = ros::WallTime::now().toSec();
        ++g_received;
      },
      ros::VoidConstPtr(), ros::TransportHints().tcpNoDelay(nodelay));
  ros::AsyncSpinner spinner(1);
  spinner.start();
  ros::AsyncSpinner out_spinner(1, &out_queue);
  if (rate_hz > 0) out_spinner.start();
  auto wait_s = [&](double s) {  // sleep, then take the outputs that came (when not paced)
    if (s > 0) std::this_thread::sleep_for(std::chrono::duration<double>(s));
    if (rate_hz <= 0) out_queue.callAvailable(ros::WallDuration(0));
  };
  if (listen_only) {
    std::printf("ready\n");
    std::fflush(stdout);
    if (in_process) {  // the bag played by the player nodelet, as fast as the compensator keeps up
      std::string bag;
      pnh.getParam("bag", bag);
      ros::param::set("/magcomp_player/bag", bag);
      ros::param::set("/magcomp_player/rate", 0.0);
      ros::param::set("/magcomp_player/topics",
                      std::vector<std::string>{"/magcomp/scalar/" + m.scalar,
                                               "/magcomp/fluxgate/" + m.vector, "/magcomp/aux"});
      ros::param::set("/magcomp_player/progress_topic", std::string("/magcomp/compensated"));
      if (!manager->load("/magcomp_player", "magcomp/Player", {}, {})) {
        std::fprintf(stderr, "bench: could not load the nodelet magcomp/Player\n");
        return 2;
      }
    }
    double last_change = ros::WallTime::now().toSec();
    long seen = 0;
    while (ros::ok() && g_received < n) {
      wait_s(0.001);
      if (g_received != seen) {
        seen = g_received;
        last_change = ros::WallTime::now().toSec();
      } else if (ros::WallTime::now().toSec() - last_change > (seen > 0 ? 10 : 60)) {
        break;
      }
    }
    double first = 1e300, last = 0;
    for (double w : g_recv_wall) {
      if (w > 0) first = std::min(first, w), last = std::max(last, w);
    }
    std::printf("%s: samples %ld, received %ld (lost %ld), %.0f samples/s (first to last output)\n",
                in_process ? "player nodelet, rate 0" : "rosbag play", static_cast<long>(n),
                static_cast<long>(g_received), static_cast<long>(n - g_received),
                (g_received - 1) / (last - first));
    return g_received == n ? 0 : 1;
  }
  while ((scalar.getNumSubscribers() == 0 || vec.getNumSubscribers() == 0 ||
          aux.getNumSubscribers() == 0 || sub.getNumPublishers() == 0) &&
         ros::ok()) {
    ros::WallDuration(0.05).sleep();
  }
  ros::WallDuration(0.5).sleep();
  std::vector<std::string> names;
  for (const auto& name : f.names()) {
    const auto needed = m.make_terms();
    bool used = false;
    for (const auto& t : needed)
      for (const auto& r : t->required_fields()) used = used || r == name;
    if (!all_channels && !used) continue;
    if (name.rfind("cur_", 0) == 0 || name.rfind("vol_", 0) == 0 || name == "diurnal")
      names.push_back(name);
  }
  const double start = ros::WallTime::now().toSec();
  const auto steady_start = std::chrono::steady_clock::now();
  for (Eigen::Index i = 0; i < n && ros::ok(); ++i) {
    wait_s(0);
    while (i - g_received > window) wait_s(0.0002);  // back-pressure
    if (rate_hz > 0) {  // one sleep to the due time (no polling: the bench must stay quiet)
      std::this_thread::sleep_until(steady_start +
                                    std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                        std::chrono::duration<double>(i / rate_hz)));
    }
    const ros::Time t = magcomp::rosio::stamp_of(year, doy, f.tt()[i]);
    // Shared pointers: a subscriber in this process (~in_process) receives them without a copy.
    const auto vp = boost::make_shared<sensor_msgs::MagneticField>();
    sensor_msgs::MagneticField& v = *vp;
    v.header.stamp = t;
    v.magnetic_field.x = f.column(m.vector + "_x")[i] * 1e-9;
    v.magnetic_field.y = f.column(m.vector + "_y")[i] * 1e-9;
    v.magnetic_field.z = f.column(m.vector + "_z")[i] * 1e-9;
    vec.publish(sensor_msgs::MagneticField::ConstPtr(vp));
    const auto ap = boost::make_shared<magcomp::AuxChannels>();
    magcomp::AuxChannels& a = *ap;
    a.header.stamp = t;
    a.names = names;
    for (const auto& k : names) a.values.push_back(f.column(k)[i]);
    aux.publish(magcomp::AuxChannels::ConstPtr(ap));
    const auto sp = boost::make_shared<magcomp::ScalarMagnetometer>();
    sp->header.stamp = t;
    sp->field_nT = f.column(m.scalar)[i];
    sent_wall[static_cast<size_t>(i)] = ros::WallTime::now().toSec();
    scalar.publish(magcomp::ScalarMagnetometer::ConstPtr(sp));
  }
  const double published = ros::WallTime::now().toSec();  // wait for the flush after the last one
  while (g_received < n && ros::ok() && ros::WallTime::now().toSec() - published < 30) {
    wait_s(0.001);
  }
  const double elapsed = ros::WallTime::now().toSec() - start;
  std::vector<double> lat;
  for (Eigen::Index i = 0; i + lookahead < n; ++i) {
    if (g_recv_wall[static_cast<size_t>(i)] > 0)
      lat.push_back(g_recv_wall[static_cast<size_t>(i)] -
                    sent_wall[static_cast<size_t>(i + lookahead)]);
  }
  std::sort(lat.begin(), lat.end());
  long shown = 0;
  for (Eigen::Index i = 0; i < n && shown < 12; ++i) {
    if (g_recv_wall[static_cast<size_t>(i)] < 0) {
      std::printf("missing sample %ld (tt %.1f)\n", static_cast<long>(i), f.tt()[i]);
      ++shown;
    }
  }
  auto pct = [&](double p) {
    return lat.empty() ? NAN : 1e3 * lat[static_cast<size_t>(p * (lat.size() - 1))];
  };
  std::printf("%s: ",
              rate_hz > 0
                  ? ("paced at " + std::to_string(static_cast<int>(rate_hz)) + " Hz").c_str()
                  : "flood");
  std::printf(
      "samples %ld, received %ld (lost %ld), %.0f samples/s end to end; latency ms: p50 %.3f p99 "
      "%.3f max %.3f\n",
      static_cast<long>(n), static_cast<long>(g_received), static_cast<long>(n - g_received),
      n / elapsed, pct(0.5), pct(0.99), pct(1.0));
  return g_received == n ? 0 : 1;
}
