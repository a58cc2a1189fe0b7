// magcomp benchmark: Tolles-Lawson fit + apply, end to end, on N samples (18 terms).
// Prints one line: samples, seconds for each stage, peak RSS in MB. Used by scripts/bench_tl.
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/math/butterworth.h"
#include "magcomp/core/model/model.h"

using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  const long n = argc > 1 ? std::atol(argv[1]) : 36000;
  magcomp::FlightData d;
  Eigen::VectorXd tt(n), bx(n), by(n), bz(n), s(n);
  for (long i = 0; i < n; ++i) {
    const double t = 0.1 * i;
    bx[i] = 17000 + 3000 * std::sin(0.05 * t) + 200 * std::sin(1.3 * t);
    by[i] = -4000 + 2500 * std::cos(0.031 * t) + 150 * std::sin(0.9 * t);
    bz[i] = 50000 + 800 * std::sin(0.021 * t);
    tt[i] = t;
    s[i] = std::sqrt(bx[i] * bx[i] + by[i] * by[i] + bz[i] * bz[i]) + 3 * std::sin(0.7 * t);
  }
  d.set("tt", tt);
  d.set("flux_c_x", bx);
  d.set("flux_c_y", by);
  d.set("flux_c_z", bz);
  d.set("mag_5_uc", s);
  magcomp::Model m;
  m.terms = {"permanent", "induced", "eddy"};
  m.fit.windows = {{-1.0, 1e12}};
  m.fit.lambda = 0.025;
  const auto t0 = Clock::now();
  magcomp::fit_model(m, {&d});
  const auto t1 = Clock::now();
  const Eigen::VectorXd comp = magcomp::compensate(m, d);
  const auto t2 = Clock::now();
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  const double fit_s = std::chrono::duration<double>(t1 - t0).count();
  const double apply_s = std::chrono::duration<double>(t2 - t1).count();
  std::printf("cpp %ld %.4f %.4f %.4f %.1f %.6f\n", n, fit_s, apply_s, fit_s + apply_s,
              ru.ru_maxrss / 1024.0, comp[n / 2]);
  return 0;
}
