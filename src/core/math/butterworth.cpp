// magcomp: Butterworth design (bilinear transform) and SOS filtering.
#include "magcomp/core/math/butterworth.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <thread>

#include "magcomp/core/error.h"

namespace magcomp {
namespace {

using cd = std::complex<double>;

// Evaluates H(z) of a cascade at z = e^{j w}.
cd response(const std::vector<Biquad>& sections, double w) {
  const cd z1 = std::polar(1.0, -w);
  const cd z2 = z1 * z1;
  cd h = 1.0;
  for (const Biquad& s : sections) {
    h *= (s.b[0] + s.b[1] * z1 + s.b[2] * z2) / (s.a[0] + s.a[1] * z1 + s.a[2] * z2);
  }
  return h;
}

// Groups z-plane poles into biquads: conjugate pairs together, real poles two by two.
std::vector<std::array<double, 2>> pole_pairs_to_denominators(std::vector<cd> poles) {
  std::vector<std::array<double, 2>> den;  // a1, a2
  std::vector<double> reals;
  std::vector<cd> upper;
  for (const cd& p : poles) {
    if (std::abs(p.imag()) < 1e-12) {
      reals.push_back(p.real());
    } else if (p.imag() > 0) {
      upper.push_back(p);
    }
  }
  for (const cd& p : upper) den.push_back({-2.0 * p.real(), std::norm(p)});
  std::sort(reals.begin(), reals.end());
  for (size_t i = 0; i + 1 < reals.size(); i += 2) {
    den.push_back({-(reals[i] + reals[i + 1]), reals[i] * reals[i + 1]});
  }
  if (reals.size() % 2 == 1) den.push_back({-reals.back(), 0.0});
  return den;
}

// One direction of the cascade over a row-major block of K columns (K independent lanes), for NS
// sections known at compile time: the state lives in registers. The same operations, in the same
// order, as the general loop in Butterworth::filtfilt, so the result is the same to the bit.
template <int NS, int K>
void sos_pass_fixed(const std::vector<Biquad>& q, const std::vector<std::array<double, 2>>& unit,
                    double* e, Eigen::Index m, Eigen::Index first, Eigen::Index step) {
  double b0[NS], b1[NS], b2[NS], a1[NS], a2[NS], z0[NS][K], z1[NS][K];
  const double* start = e + first * K;
  for (int s = 0; s < NS; ++s) {
    b0[s] = q[static_cast<size_t>(s)].b[0];
    b1[s] = q[static_cast<size_t>(s)].b[1];
    b2[s] = q[static_cast<size_t>(s)].b[2];
    a1[s] = q[static_cast<size_t>(s)].a[1];
    a2[s] = q[static_cast<size_t>(s)].a[2];
    for (int c = 0; c < K; ++c) {
      z0[s][c] = unit[static_cast<size_t>(s)][0] * start[c];
      z1[s][c] = unit[static_cast<size_t>(s)][1] * start[c];
    }
  }
  double* row = e + first * K;
  const Eigen::Index stride = step * K;
  for (Eigen::Index r = 0; r < m; ++r, row += stride) {
    for (int s = 0; s < NS; ++s) {
      for (int c = 0; c < K; ++c) {
        const double v = row[c];
        const double y = b0[s] * v + z0[s][c];
        z0[s][c] = b1[s] * v - a1[s] * y + z1[s][c];
        z1[s][c] = b2[s] * v - a2[s] * y;
        row[c] = y;
      }
    }
  }
}

// The fixed-size pass for a band-pass of order 4 (four sections) over 1 to 4 columns, the shape
// of a candidate term's columns in diagnose; false for any other shape.
bool sos_pass_small(const std::vector<Biquad>& q, const std::vector<std::array<double, 2>>& unit,
                    double* e, Eigen::Index k, Eigen::Index m, Eigen::Index first,
                    Eigen::Index step) {
  using Pass = void (*)(const std::vector<Biquad>&, const std::vector<std::array<double, 2>>&,
                        double*, Eigen::Index, Eigen::Index, Eigen::Index);
  static constexpr Pass kByColumns[] = {sos_pass_fixed<4, 1>, sos_pass_fixed<4, 2>,
                                        sos_pass_fixed<4, 3>, sos_pass_fixed<4, 4>};
  if (q.size() != 4 || k < 1 || k > 4) return false;
  kByColumns[k - 1](q, unit, e, m, first, step);
  return true;
}

}  // namespace

Butterworth::Butterworth(FilterType type, int order, double low_hz, double high_hz, double fs) {
  if (order < 1 || order > 20)
    throw Error("filter: order " + std::to_string(order) + " not in 1..20");

  if (!(fs > 0)) throw Error("filter: sample_rate_hz must be positive");
  const double nyq = fs / 2.0;
  auto check = [&](double f, const char* what) {
    // Below 1e-6 of the Nyquist frequency the digital poles merge with z = 1 in double precision.
    if (!(f >= 1e-6 * nyq && f < nyq)) {
      char buf[200];
      std::snprintf(buf, sizeof(buf), "filter: %s = %g Hz must lie in [%g, %g) Hz", what, f,
                    1e-6 * nyq, nyq);
      throw Error(buf);
    }
  };
  sample_rate_hz_ = fs;
  check(low_hz, type == FilterType::kBandPass ? "low cut-off" : "cut-off");
  if (type == FilterType::kBandPass) {
    check(high_hz, "high cut-off");
    if (!(high_hz > low_hz)) throw Error("filter: band high cut-off must exceed the low one");
  }
  // Analog prototype poles on the unit circle, left half-plane.
  std::vector<cd> proto;
  for (int k = 0; k < order; ++k) {
    const double theta = M_PI * (2.0 * k + order + 1) / (2.0 * order);
    proto.push_back(std::polar(1.0, theta));
  }
  const double two_fs = 2.0 * fs;
  auto warp = [&](double f) { return two_fs * std::tan(M_PI * f / fs); };
  std::vector<cd> analog;
  double numerator_zero = 0.0;  // z of the finite zeros: -1 (low-pass), +1 (high-pass)
  double w_norm = 0.0;          // digital frequency (rad/sample) where |H| = 1
  if (type == FilterType::kLowPass) {
    const double wc = warp(low_hz);
    for (const cd& p : proto) analog.push_back(p * wc);
    numerator_zero = -1.0;
    w_norm = 0.0;
  } else if (type == FilterType::kHighPass) {
    const double wc = warp(low_hz);
    for (const cd& p : proto) analog.push_back(wc / p);
    numerator_zero = 1.0;
    w_norm = M_PI;
  } else {
    const double w1 = warp(low_hz), w2 = warp(high_hz);
    const double bw = w2 - w1, w0 = std::sqrt(w1 * w2);
    for (const cd& p : proto) {
      const cd half = p * bw / 2.0;
      const cd root = std::sqrt(half * half - w0 * w0);
      analog.push_back(half + root);
      analog.push_back(half - root);
    }
    w_norm = 2.0 * std::atan(w0 / two_fs);
  }
  std::vector<cd> digital;
  for (const cd& s : analog) digital.push_back((two_fs + s) / (two_fs - s));
  for (const auto& den : pole_pairs_to_denominators(digital)) {
    Biquad q;
    q.a = {1.0, den[0], den[1]};
    const bool second_order = den[1] != 0.0;
    if (type == FilterType::kBandPass) {
      q.b = {1.0, 0.0, -1.0};  // one zero at z = 1 (s = 0) and one at z = -1 (s = inf)
    } else if (second_order) {
      q.b = {1.0, -2.0 * numerator_zero, 1.0};
    } else {
      q.b = {1.0, -numerator_zero, 0.0};
    }
    sections_.push_back(q);
  }
  const double gain = 1.0 / std::abs(response(sections_, w_norm));
  for (double& c : sections_.front().b) c *= gain;
}

Butterworth Butterworth::low_pass(int order, double cutoff_hz, double fs) {
  return Butterworth(FilterType::kLowPass, order, cutoff_hz, 0.0, fs);
}
Butterworth Butterworth::high_pass(int order, double cutoff_hz, double fs) {
  return Butterworth(FilterType::kHighPass, order, cutoff_hz, 0.0, fs);
}
Butterworth Butterworth::band_pass(int order, double low_hz, double high_hz, double fs) {
  return Butterworth(FilterType::kBandPass, order, low_hz, high_hz, fs);
}

double Butterworth::magnitude(double f_hz) const {
  return std::abs(response(sections_, 2.0 * M_PI * f_hz / sample_rate_hz_));
}

std::vector<std::array<double, 2>> Butterworth::step_state() const {
  // Steady state of each DF2T section for a constant input; the input to the next section is
  // the previous DC gain times the step.
  std::vector<std::array<double, 2>> zi;
  double scale = 1.0;
  for (const Biquad& s : sections_) {
    const double dc = (s.b[0] + s.b[1] + s.b[2]) / (1.0 + s.a[1] + s.a[2]);
    // y = dc * u; z1 = y - b0 u ... from y = b0 u + z0, z0' = b1 u - a1 y + z1, z1' = b2 u - a2 y.
    const double u = scale;
    const double y = dc * u;
    const double z1 = s.b[2] * u - s.a[2] * y;
    const double z0 = s.b[1] * u - s.a[1] * y + z1;
    zi.push_back({z0, z1});
    scale = y;
  }
  return zi;
}

namespace {

// In-place DF2T cascade over x with the given initial state per section.
void run_sections(const std::vector<Biquad>& sections, std::vector<std::array<double, 2>> state,
                  std::vector<double>& x) {
  for (size_t k = 0; k < sections.size(); ++k) {
    const Biquad& s = sections[k];
    double z0 = state[k][0], z1 = state[k][1];
    for (double& v : x) {
      const double y = s.b[0] * v + z0;
      z0 = s.b[1] * v - s.a[1] * y + z1;
      z1 = s.b[2] * v - s.a[2] * y;
      v = y;
    }
  }
}

std::vector<std::array<double, 2>> scaled(const std::vector<std::array<double, 2>>& unit,
                                          double value) {
  std::vector<std::array<double, 2>> out = unit;
  for (auto& z : out) {
    z[0] *= value;
    z[1] *= value;
  }
  return out;
}

}  // namespace

Eigen::VectorXd Butterworth::filtfilt(const Eigen::VectorXd& x) const {
  const Eigen::Index n = x.size();
  if (n == 0) return x;
  const Eigen::Index pad =
      std::min<Eigen::Index>(3 * (2 * static_cast<Eigen::Index>(sections_.size()) + 1), n - 1);
  std::vector<double> ext(static_cast<size_t>(n + 2 * pad));
  for (Eigen::Index i = 0; i < pad; ++i) {
    ext[static_cast<size_t>(i)] = 2.0 * x[0] - x[pad - i];
    ext[static_cast<size_t>(n + pad + i)] = 2.0 * x[n - 1] - x[n - 2 - i];
  }
  for (Eigen::Index i = 0; i < n; ++i) ext[static_cast<size_t>(pad + i)] = x[i];
  const auto unit = step_state();
  run_sections(sections_, scaled(unit, ext.front()), ext);
  std::reverse(ext.begin(), ext.end());
  run_sections(sections_, scaled(unit, ext.front()), ext);
  std::reverse(ext.begin(), ext.end());
  Eigen::VectorXd y(n);
  for (Eigen::Index i = 0; i < n; ++i) y[i] = ext[static_cast<size_t>(pad + i)];
  return y;
}

Eigen::MatrixXd Butterworth::filtfilt(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
  // All columns at once: a row-major block whose columns are independent lanes, so the inner loop
  // vectorises and the recursion's latency is hidden. Same scheme as the vector version.
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const Eigen::Index n = x.rows(), k = x.cols();
  if (n == 0 || k == 0) return x;
  const Eigen::Index pad =
      std::min<Eigen::Index>(3 * (2 * static_cast<Eigen::Index>(sections_.size()) + 1), n - 1);
  const Eigen::Index m = n + 2 * pad;
  RowMajor e(m, k);
  e.middleRows(pad, n) = x;
  for (Eigen::Index i = 0; i < pad; ++i) {
    e.row(i) = 2.0 * x.row(0) - x.row(pad - i);
    e.row(n + pad + i) = 2.0 * x.row(n - 1) - x.row(n - 2 - i);
  }
  const auto unit = step_state();
  if (sos_pass_small(sections_, unit, e.data(), k, m, 0, 1)) {
    sos_pass_small(sections_, unit, e.data(), k, m, m - 1, -1);
    return e.middleRows(pad, n);
  }
  const size_t ns = sections_.size();
  std::vector<double> z0(ns * static_cast<size_t>(k)), z1(z0.size());
  auto pass = [&](Eigen::Index first, Eigen::Index step) {
    const double* start = e.row(first).data();
    for (size_t s = 0; s < ns; ++s) {
      for (Eigen::Index c = 0; c < k; ++c) {
        z0[s * k + c] = unit[s][0] * start[c];
        z1[s * k + c] = unit[s][1] * start[c];
      }
    }
    for (Eigen::Index r = 0, i = first; r < m; ++r, i += step) {
      double* __restrict row = e.row(i).data();
      for (size_t s = 0; s < ns; ++s) {
        const Biquad& q = sections_[s];
        double* __restrict a = z0.data() + s * k;
        double* __restrict b = z1.data() + s * k;
        for (Eigen::Index c = 0; c < k; ++c) {
          const double v = row[c];
          const double y = q.b[0] * v + a[c];
          a[c] = q.b[1] * v - q.a[1] * y + b[c];
          b[c] = q.b[2] * v - q.a[2] * y;
          row[c] = y;
        }
      }
    }
  };
  pass(0, 1);
  pass(m - 1, -1);
  return e.middleRows(pad, n);
}

Eigen::MatrixXd Butterworth::filtfilt_parallel(const Eigen::Ref<const Eigen::MatrixXd>& x,
                                               int threads) const {
  const Eigen::Index k = x.cols();
  threads = static_cast<int>(std::min<Eigen::Index>(std::max(threads, 1), k));
  if (threads <= 1 || x.rows() * k < 200000) return filtfilt(x);
  Eigen::MatrixXd y(x.rows(), k);
  std::vector<std::thread> pool;
  const Eigen::Index per = (k + threads - 1) / threads;
  for (Eigen::Index c0 = 0; c0 < k; c0 += per) {
    const Eigen::Index w = std::min(per, k - c0);
    pool.emplace_back([&, c0, w] {
      y.middleCols(c0, w) = filtfilt(Eigen::Ref<const Eigen::MatrixXd>(x.middleCols(c0, w)));
    });
  }
  for (auto& t : pool) t.join();
  return y;
}

Eigen::VectorXd Butterworth::filter(const Eigen::VectorXd& x) const {
  std::vector<double> v(x.data(), x.data() + x.size());
  if (!v.empty()) run_sections(sections_, scaled(step_state(), v.front()), v);
  return Eigen::Map<Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

StreamingFilter::StreamingFilter(const Butterworth& filter)
    : sections_(filter.sections()), unit_state_(filter.step_state()), state_(unit_state_) {}

double StreamingFilter::step(double x) {
  if (!primed_) {
    state_ = scaled(unit_state_, x);
    primed_ = true;
  }
  double v = x;
  for (size_t k = 0; k < sections_.size(); ++k) {
    const Biquad& s = sections_[k];
    auto& z = state_[k];
    const double y = s.b[0] * v + z[0];
    z[0] = s.b[1] * v - s.a[1] * y + z[1];
    z[1] = s.b[2] * v - s.a[2] * y;
    v = y;
  }
  return v;
}

}  // namespace magcomp
