// magcomp: the Rao-Blackwellised particle filter for a start far from the truth
// (particle_filter.h).
#include "magcomp/core/nav/particle_filter.h"

#include <algorithm>
#include <cmath>

#include "magcomp/core/error.h"
#include "magcomp/core/nav/nav_model.h"

namespace magcomp::nav {
namespace {
constexpr double kOffMapLogWeight = -6.0;  // a particle off the map: e^-6 of a fitting one
}  // namespace

ParticleFilter::ParticleFilter(const AnomalyMap& map, const ParticleSettings& s)
    : map_(map), s_(s), rng_(s.seed) {
  if (s.particles < 10 || s.particles > 1000000)
    throw Error("particle filter: particles must be in 10..1000000");
  require_setting(s.init_sigma_m, 0, kMaxPositionSigma_m, "particle filter: init_sigma_m", "m");
  require_setting(s.walk_m_per_sqrt_s, 0, 1e3, "particle filter: walk", "m/sqrt(s)", true);
  require_setting(s.offset_sigma_nT, 0, kMaxSigma_nT, "particle filter: offset_sigma", "nT");
  require_setting(s.handover_sigma_m, 0, kMaxPositionSigma_m, "particle filter: handover", "m");
  reset();
}

void ParticleFilter::reset() {
  const auto n = static_cast<size_t>(s_.particles);
  std::normal_distribution<double> g(0.0, s_.init_sigma_m);
  offset_.resize(n);
  for (auto& o : offset_) o = Eigen::Vector2d(g(rng_), g(rng_));
  bias_.assign(n, 0.0);
  bias_var_.assign(n, s_.offset_sigma_nT * s_.offset_sigma_nT);
  log_w_.assign(n, 0.0);
  walk_s_ = 0.0;
}

void ParticleFilter::step(double lat, double lon, double z, double r, double dt) {
  const size_t n = offset_.size();
  // The walk is metres against a cloud of tens to thousands: it is drawn where it matters, when
  // the copies of a resampling need telling apart, for all the time since the last one.
  if (dt > 0) walk_s_ += dt;
  if (!std::isfinite(z) || !(r > 0)) return;
  const double north_per_rad = dlat_to_north_m(1.0, lat), east_per_rad = dlon_to_east_m(1.0, lat);
  for (size_t i = 0; i < n; ++i) {
    const double la = lat + offset_[i].x() / north_per_rad;
    const double lo = lon + offset_[i].y() / east_per_rad;
    double m = 0;
    if (!map_.covered_value(la, lo, &m)) {
      log_w_[i] += kOffMapLogWeight;
      continue;
    }
    // The offset's Kalman filter given this position: its innovation weighs the particle.
    const double v = z - m - bias_[i];
    const double sv = bias_var_[i] + r;
    log_w_[i] += -0.5 * (v * v / sv + std::log(sv));
    const double k = bias_var_[i] / sv;
    bias_[i] += k * v;
    bias_var_[i] *= 1 - k;
  }
  const double top = *std::max_element(log_w_.begin(), log_w_.end());
  double sum = 0, sum2 = 0;
  for (double& w : log_w_) {
    w -= top;  // the largest at 0: no underflow of the sums
    const double e = std::exp(w);
    sum += e;
    sum2 += e * e;
  }
  if (sum * sum / sum2 < 0.5 * static_cast<double>(n)) resample();
}

void ParticleFilter::resample() {
  // Systematic resampling; the walk since the last one keeps the copies apart.
  const size_t n = offset_.size();
  std::vector<double> cum(n);
  double sum = 0;
  for (size_t i = 0; i < n; ++i) cum[i] = (sum += std::exp(log_w_[i]));
  std::uniform_real_distribution<double> u(0.0, sum / static_cast<double>(n));
  std::normal_distribution<double> jitter(0.0, s_.walk_m_per_sqrt_s * std::sqrt(walk_s_) + 1e-3);
  walk_s_ = 0.0;
  const double start = u(rng_);
  std::vector<Eigen::Vector2d> o(n);
  std::vector<double> b(n), bv(n);
  size_t j = 0;
  for (size_t i = 0; i < n; ++i) {
    const double target = start + static_cast<double>(i) * sum / static_cast<double>(n);
    while (j + 1 < n && cum[j] < target) ++j;
    o[i] = offset_[j] + Eigen::Vector2d(jitter(rng_), jitter(rng_));
    b[i] = bias_[j];
    bv[i] = bias_var_[j];
  }
  offset_.swap(o);
  bias_.swap(b);
  bias_var_.swap(bv);
  log_w_.assign(n, 0.0);
}

ParticleEstimate ParticleFilter::estimate() const {
  ParticleEstimate e;
  const size_t n = offset_.size();
  double sum = 0, sum2 = 0;
  for (size_t i = 0; i < n; ++i) {
    const double w = std::exp(log_w_[i]);
    sum += w;
    sum2 += w * w;
    e.offset_m += w * offset_[i];
    e.measurement_offset_nT += w * bias_[i];
  }
  e.offset_m /= sum;
  e.measurement_offset_nT /= sum;
  for (size_t i = 0; i < n; ++i) {
    const double w = std::exp(log_w_[i]) / sum;
    const Eigen::Vector2d d = offset_[i] - e.offset_m;
    e.covariance_m2 += w * d * d.transpose();
    const double db = bias_[i] - e.measurement_offset_nT;
    e.measurement_offset_var_nT2 += w * (bias_var_[i] + db * db);
  }
  e.effective_particles = sum * sum / sum2;
  e.gathered = std::sqrt(e.covariance_m2.trace()) < s_.handover_sigma_m &&
               e.effective_particles > 0.05 * static_cast<double>(n);
  return e;
}

}  // namespace magcomp::nav
