// libFuzzer target: `magcomp navigate`'s path from a flight's columns to its scores, on arbitrary
// columns (any stamps, duplicates, gaps, NaN, inf, poles, values of 1e300): flight_samples, the
// run through the streaming navigator, the bound along the truth, the scores. Every step output
// must be finite, every score finite or NaN (nothing to compute it from); a crash, an exception
// other than magcomp::Error, or an infinite score is a finding.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "magcomp/core/error.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/flight_run.h"
#include "magcomp/core/nav/nav_model.h"

namespace {

using namespace magcomp;

const nav::AnomalyMap& test_map() {
  static const nav::AnomalyMap m = [] {
    nav::AnomalyMap a;
    const int n = 24;
    a.lat_rad.resize(n);
    a.lon_rad.resize(n);
    for (int i = 0; i < n; ++i) {
      a.lat_rad[i] = (45.0 + 0.002 * i) * kDegToRad;
      a.lon_rad[i] = (-75.0 + 0.002 * i) * kDegToRad;
    }
    a.map_nT.resize(n, n);
    a.mask = Eigen::MatrixXd::Ones(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) a.map_nT(i, j) = 40 * std::sin(0.4 * i + 0.1 * j);
    a.mask(5, 5) = 0;
    a.alt_m = 300;
    return a;
  }();
  return m;
}

bool bad_score(double v) { return std::isinf(v); }

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  // Rows of 14 bytes: per column a byte offset from a plausible value, or (flag) a raw double.
  const size_t rows = std::min<size_t>(size / 14, 12);
  if (rows < 2) return 0;
  const char* names[] = {"tt",      "lat",     "lon",      "alt",       "ins_lat",
                         "ins_lon", "ins_alt", "ins_roll", "ins_pitch", "ins_yaw",
                         "anomaly", "roll",    "pitch",    "yaw"};
  const double base[] = {0, 45.02, -74.98, 300, 45.02, -74.98, 300, 0, 0, 0, 10, 0, 0, 0};
  const double step[] = {0.1, 1e-4, 1e-4, 1, 1e-4, 1e-4, 1, 0.5, 0.5, 2, 1, 0.5, 0.5, 2};
  FlightData f;
  for (int c = 0; c < 14; ++c) {
    Eigen::VectorXd v(static_cast<Eigen::Index>(rows));
    for (size_t i = 0; i < rows; ++i) {
      const uint8_t b = data[i * 14 + static_cast<size_t>(c)];
      double x = base[c] + (c == 0 ? static_cast<double>(i) * step[c] : 0) +
                 (static_cast<int>(b & 0x7f) - 64) * step[c] * (c == 0 ? 0.1 : 1);
      if (b == 0xff) x = NAN;
      if (b == 0xfe) x = INFINITY;
      if (b == 0xfd) x = c == 4 || c == 1 ? 90.0 : 1e300;
      v[static_cast<Eigen::Index>(i)] = x;
    }
    if (c == 0) {  // the reader's contract: tt finite and sorted
      for (Eigen::Index i = 0; i < v.size(); ++i)
        if (!std::isfinite(v[i])) v[i] = static_cast<double>(i) * 0.1;
      std::sort(v.data(), v.data() + v.size());
    }
    f.set(names[c], v);
  }
  try {
    const nav::FlightSamples s = nav::flight_samples(f);
    nav::FilterSettings settings = nav::filter_model(0.1, 45.02 * kDegToRad, nav::ModelSigmas{});
    settings.offset_from_first = data[0] & 1;
    const Eigen::VectorXd z = f.column("anomaly");
    const nav::FlightRun run = nav::run_flight(s.ins, z, nullptr, test_map(), settings, s.dt_s);
    const nav::FlightRun bound = nav::crlb_run(s.truth, test_map(), settings, s.dt_s);
    for (const auto* r : {&run, &bound})
      for (const auto& o : r->steps)
        if (!std::isfinite(o.lat_rad) || !o.position_cov_ned_m2.allFinite()) std::abort();
    const nav::NavigationScores sc = nav::score_run(run, bound, s, z, test_map());
    for (double v :
         {sc.measurement_minus_map_std_nT, sc.drms_filter_m, sc.drms_ins_m, sc.drms_crlb_m,
          sc.nees_in_bounds, sc.innovation_mean_nT, sc.innovation_std_nT, sc.nis_mean})
      if (bad_score(v)) std::abort();
  } catch (const magcomp::Error&) {
  }
  return 0;
}
