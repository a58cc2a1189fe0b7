// magcomp benchmark: the map-matching EKF's speed. MagNav.jl's simple example (100 samples)
// repeated to one hour at 10 Hz (36,000 filter steps at dt = 0.1 s) on one core; prints the time
// per step and the multiple of real time.
// Usage: magcomp_bench_nav SIMPLE_XYZ.h5 SIMPLE_MAP.h5   (scripts/bench_nav)
#include <chrono>
#include <cstdio>

#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/nav_model.h"

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
    const nav::FilterSettings s = nav::filter_model(dt, ins.lat_rad[0], nav::ModelSigmas{});
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
  } catch (const std::exception& e) {
    std::fprintf(stderr, "magcomp_bench_nav: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
