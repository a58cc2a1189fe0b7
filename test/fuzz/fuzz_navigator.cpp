// libFuzzer target: the streaming navigator (what the navigator node's message handlers feed) on
// an arbitrary sequence of INS samples and measurements, in any order, with any stamps and any
// values (NaN, inf, poles, 1e300). Every output must be finite: a NaN position or covariance, a
// crash or an exception is a finding.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "magcomp/core/error.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/streaming_navigator.h"

namespace {

using namespace magcomp;

// A smooth 32 x 32 map about (45 N, 75 W), 0.001 deg cells, 300 m up.
const nav::AnomalyMap& test_map() {
  static const nav::AnomalyMap m = [] {
    nav::AnomalyMap a;
    const int n = 32;
    a.lat_rad.resize(n);
    a.lon_rad.resize(n);
    for (int i = 0; i < n; ++i) {
      a.lat_rad[i] = (45.0 + 0.001 * i) * kDegToRad;
      a.lon_rad[i] = (-75.0 + 0.001 * i) * kDegToRad;
    }
    a.map_nT.resize(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) a.map_nT(i, j) = 50 * std::sin(0.3 * i) * std::cos(0.2 * j);
    a.alt_m = 300;
    return a;
  }();
  return m;
}

// Reads doubles from the input: raw bit patterns (any NaN or inf), or small offsets.
struct Reader {
  const uint8_t* p;
  size_t n;
  bool more() const { return n > 0; }
  uint8_t byte() {
    if (!n) return 0;
    --n;
    return *p++;
  }
  double raw() {
    double v = 0;
    if (n >= 8) {
      std::memcpy(&v, p, 8);
      p += 8;
      n -= 8;
    }
    return v;
  }
  double offset(double scale) { return (static_cast<int>(byte()) - 128) * scale; }
};

bool finite(const nav::NavigatorOutput& o) {
  return std::isfinite(o.lat_rad) && std::isfinite(o.lon_rad) && std::isfinite(o.alt_m) &&
         o.position_cov_ned_m2.allFinite() && o.velocity_ned_mps.allFinite();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader r{data, size};
  const double dt = 0.1;
  nav::FilterSettings s = nav::filter_model(dt, 45.01 * kDegToRad, nav::ModelSigmas{});
  s.offset_from_first = r.byte() & 1;
  nav::StreamingNavigator nav(test_map(), s, dt);
  double t = 1000.0;
  long ops = 0;
  while (r.more() && ++ops < 16) {
    std::vector<nav::NavigatorOutput> out;
    const uint8_t op = r.byte();
    switch (op % 8) {
      case 0:
      case 1:
      case 2: {  // a plausible INS sample near the map, the stamp stepping on
        t += dt * (1 + (op >> 6));
        nav::InsSample x;
        x.t_s = t;
        x.lat_rad = (45.015 + r.offset(1e-4)) * kDegToRad;
        x.lon_rad = (-74.985 + r.offset(1e-4)) * kDegToRad;
        x.alt_m = 300 + r.offset(1.0);
        x.roll_rad = r.offset(0.01);
        x.pitch_rad = r.offset(0.01);
        x.yaw_rad = r.offset(0.03);
        out = nav.push_ins(x);
        break;
      }
      case 3: {  // an INS sample of raw values (NaN, inf, poles, any stamp)
        nav::InsSample x;
        x.t_s = (op & 0x80) ? r.raw() : t + r.offset(0.05);
        x.lat_rad = r.raw();
        x.lon_rad = r.raw();
        x.alt_m = r.raw();
        x.roll_rad = r.raw();
        x.pitch_rad = r.raw();
        x.yaw_rad = r.raw();
        out = nav.push_ins(x);
        break;
      }
      case 4:
      case 5:  // a measurement at a recent stamp
        out = nav.push_measurement(t - dt * (op >> 5), 20 + r.offset(0.5), NAN);
        break;
      case 6:  // a measurement of raw values
        out = nav.push_measurement((op & 0x80) ? r.raw() : t, r.raw(), r.raw());
        break;
      default:
        out = (op & 0x10) ? nav.flush() : (op & 0x20) ? nav.end_of_ins() : out;
        if (op & 0x40) nav.reset();
        break;
    }
    for (const auto& o : out)
      if (!finite(o)) std::abort();
  }
  for (const auto& o : nav.flush())
    if (!finite(o)) std::abort();
  return 0;
}
