// magcomp benchmark: the map-matching EKF's speed. MagNav.jl's simple example (100 samples)
// repeated to one hour at 10 Hz (36,000 filter steps at dt = 0.1 s) on one core; prints the time
// per step and the multiple of real time.
// Usage: magcomp_bench_nav SIMPLE_XYZ.h5 SIMPLE_MAP.h5   (scripts/bench_nav)
#include <chrono>
#include <cmath>
#include <cstdio>

#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/flight_run.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/particle_filter.h"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s SIMPLE_XYZ.h5 SIMPLE_MAP.h5\n", argv[0]);
    return 2;
  }
  using namespace magcomp;
  try {
    auto col = [&](const char* name) {
      const H5Array a = read_h5_array(argv[1], name);
      return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(
          a.values.data(), static_cast<Eigen::Index>(a.values.size())));
    };
    const int reps = 360;  // 100 samples x 360 = 36,000 steps
    auto tile = [&](const Eigen::VectorXd& v) { return Eigen::VectorXd(v.replicate(reps, 1)); };
    const double dt = 0.1;
    const nav::NavTrack ins = nav::track_from_positions(
        dt, tile(col("ins_lat")) * kDegToRad, tile(col("ins_lon")) * kDegToRad,
        tile(col("ins_alt")), tile(col("ins_roll")) * kDegToRad, tile(col("ins_pitch")) * kDegToRad,
        tile(col("ins_yaw")) * kDegToRad);
    const Eigen::VectorXd meas = tile(col("mag_1_c"));
    const nav::AnomalyMap map = nav::read_anomaly_map(argv[2]);
    nav::ModelSigmas sigmas;
    sigmas.map_representation_var = true;  // navigate's and the node's default R
    const nav::FilterSettings s = nav::filter_model(dt, ins.lat_rad[0], sigmas);
    for (int run = 0; run < 3; ++run) {
      const auto t0 = std::chrono::steady_clock::now();
      const nav::FilterResult r = nav::run_ekf(ins, meas, map, s);
      const double secs =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double flight_s = static_cast<double>(ins.size()) * dt;
      std::printf("steps %ld  seconds %.3f  us_per_step %.1f  x_real_time_at_10Hz %.0f  (x %.2e)\n",
                  static_cast<long>(ins.size()), secs, 1e6 * secs / static_cast<double>(ins.size()),
                  flight_s / secs, r.x(0, r.x.cols() - 1));
    }
    // Online calibration: the same steps with 30 coefficient states (48 in all), the columns
    // drawn at random (their values do not change the work), through the streaming navigator.
    std::vector<nav::InsSample> samples;
    const Eigen::VectorXd lat = tile(col("ins_lat")) * kDegToRad,
                          lon = tile(col("ins_lon")) * kDegToRad, alt = tile(col("ins_alt")),
                          roll = tile(col("ins_roll")) * kDegToRad,
                          pitch = tile(col("ins_pitch")) * kDegToRad,
                          yaw = tile(col("ins_yaw")) * kDegToRad;
    for (Eigen::Index i = 0; i < lat.size(); ++i)
      samples.push_back(
          {static_cast<double>(i) * dt, lat[i], lon[i], alt[i], roll[i], pitch[i], yaw[i]});
    nav::FilterSettings online = s;
    const int k = 30;
    online.c0 = Eigen::VectorXd::Zero(k);
    online.pc0 = Eigen::MatrixXd::Identity(k, k) * 100.0;
    online.qc_per_s = Eigen::VectorXd::Zero(k);
    const Eigen::MatrixXd columns = Eigen::MatrixXd::Random(lat.size(), k) * 0.01;
    for (int run = 0; run < 2; ++run) {
      const auto t0 = std::chrono::steady_clock::now();
      const nav::FlightRun r = nav::run_flight(samples, meas, nullptr, map, online, dt, &columns);
      const double secs =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::printf(
          "online 18+%d states: steps %zu  seconds %.3f  us_per_step %.1f  x_real_time_at_10Hz "
          "%.0f\n",
          k, r.steps.size(), secs, 1e6 * secs / static_cast<double>(r.steps.size()),
          static_cast<double>(samples.size()) * dt / secs);
    }
    // The particle filter of a cold start: 20,000 particles, 3,000 steps (5 min at 10 Hz).
    nav::ParticleSettings ps;
    ps.init_sigma_m = 2000.0;
    for (int run = 0; run < 2; ++run) {
      nav::ParticleFilter pf(map, ps);
      const int steps = 3000;
      const auto t0 = std::chrono::steady_clock::now();
      for (int i = 0; i < steps; ++i) pf.step(lat[i], lon[i], meas[i], 9.0, dt);
      const nav::ParticleEstimate e = pf.estimate();
      const double secs =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::printf(
          "particle filter %d particles: steps %d  seconds %.3f  us_per_step %.0f  "
          "x_real_time_at_10Hz %.0f  (sigma %.0f m)\n",
          ps.particles, steps, secs, 1e6 * secs / steps, steps * dt / secs,
          std::sqrt(e.covariance_m2.trace()));
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "magcomp_bench_nav: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
