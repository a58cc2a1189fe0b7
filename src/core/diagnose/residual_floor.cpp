// magcomp: a held-out residual's noise floor (from its spectrum) and the channel its power follows.
#include "magcomp/core/diagnose/residual_floor.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numeric>
#include <set>
#include <string>
#include <tuple>
#include <unsupported/Eigen/FFT>
#include <utility>

#include "magcomp/core/math/constants.h"
#include "magcomp/core/math/correlation.h"

namespace magcomp {
namespace {

constexpr int kSegment = 256;         // samples per spectral segment (25.6 s at 10 Hz)
constexpr int kWindow_s = 10;         // local-variance windows, s
constexpr double kMinRankCorr = 0.3;  // a weaker rank correlation is not reported

// Contiguous runs [first, last) of one held-out unit each, in time order.
std::vector<std::pair<Eigen::Index, Eigen::Index>> unit_runs(const std::vector<int>& unit,
                                                             const Eigen::VectorXd& r) {
  std::vector<std::pair<Eigen::Index, Eigen::Index>> runs;
  const auto n = static_cast<Eigen::Index>(unit.size());
  Eigen::Index i = 0;
  while (i < n) {
    if (unit[static_cast<size_t>(i)] < 0 || !std::isfinite(r[i])) {
      ++i;
      continue;
    }
    Eigen::Index j = i + 1;
    while (j < n && unit[static_cast<size_t>(j)] == unit[static_cast<size_t>(i)] &&
           std::isfinite(r[j]))
      ++j;
    runs.emplace_back(i, j);
    i = j;
  }
  return runs;
}

// The channel whose mean over each window (first sample, length) best ranks `levels` (Spearman),
// when |rho| reaches `threshold`; position channels left out. Empty name and 0 otherwise.
std::pair<std::string, double> channel_ranking(
    const std::vector<double>& levels,
    const std::vector<std::pair<Eigen::Index, Eigen::Index>>& windows,
    const std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>>& channels,
    double threshold) {
  std::pair<std::string, double> best{"", 0.0};
  const Eigen::VectorXd lv = ranks(
      Eigen::Map<const Eigen::VectorXd>(levels.data(), static_cast<Eigen::Index>(levels.size())));
  for (const auto& [name, values] : channels) {
    if (is_position_channel(name)) continue;
    Eigen::VectorXd m(static_cast<Eigen::Index>(windows.size()));
    bool finite = true;
    for (size_t w = 0; w < windows.size(); ++w) {
      const auto& [s, len] = windows[w];
      const double v = values.segment(s, len).mean();
      finite = finite && std::isfinite(v);
      m[static_cast<Eigen::Index>(w)] = v;
    }
    if (!finite) continue;
    const double rho = pearson(lv, ranks(m));
    if (std::abs(rho) >= threshold && std::abs(rho) > std::abs(best.second)) best = {name, rho};
  }
  return best;
}

}  // namespace

ResidualFloor residual_floor(
    const Eigen::VectorXd& residual, const std::vector<int>& unit, double sample_rate_hz,
    const std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>>& channels,
    double band_lo_fraction) {
  ResidualFloor out;
  if (!(sample_rate_hz > 0) || static_cast<Eigen::Index>(unit.size()) != residual.size())
    return out;
  const auto runs = unit_runs(unit, residual);
  // The residual's std, each unit's mean removed.
  double ss = 0;
  long n = 0;
  for (const auto& [a, b] : runs) {
    const double mean = residual.segment(a, b - a).mean();
    ss += (residual.segment(a, b - a).array() - mean).square().sum();
    n += b - a;
  }
  if (n < 2) return out;
  out.residual_std_nT = std::sqrt(ss / static_cast<double>(n - 1));

  // Each detrended, Hann-windowed segment's periodogram (one-sided, nT^2/Hz), and its median
  // level over the frequencies above band_lo_hz. The floor is the median of those levels over the
  // segments: a sensor's noise is in every segment, while an effect that lives in some segments
  // only (a relay chattering while its channel sits at the threshold, a burst of interference)
  // raises an averaged spectrum but not the typical segment's.
  Eigen::VectorXd w(kSegment);
  for (int k = 0; k < kSegment; ++k) w[k] = 0.5 - 0.5 * std::cos(2 * kPi * k / kSegment);
  const double w2 = w.squaredNorm();
  const double nyquist = 0.5 * sample_rate_hz;
  out.band_lo_hz = band_lo_fraction * nyquist;
  std::vector<int> bins;
  for (int k = 1; k < kSegment / 2; ++k)
    if (k * sample_rate_hz / kSegment >= out.band_lo_hz) bins.push_back(k);
  if (bins.empty()) return out;
  // The median of B exponential values (a white noise's periodogram over B frequencies) is the
  // order statistic r = B/2 + 1 (the one nth_element picks at B/2): mean sum_{j<r} 1/(B - j)
  // times the level.
  const size_t nb = bins.size(), r = nb / 2 + 1;
  double median_mean = 0;
  for (size_t j = 0; j < r; ++j) median_mean += 1.0 / static_cast<double>(nb - j);
  Eigen::FFT<double> fft;
  std::vector<double> seg(kSegment), band(nb), levels;
  std::vector<std::pair<Eigen::Index, Eigen::Index>> segments;  // first sample, length
  std::vector<std::complex<double>> spec;
  Eigen::VectorXd x(kSegment), tk(kSegment);
  for (int k = 0; k < kSegment; ++k) tk[k] = k - 0.5 * (kSegment - 1);
  const double stt = tk.squaredNorm();
  for (const auto& [a, b] : runs) {
    for (Eigen::Index s = a; s + kSegment <= b; s += kSegment / 2) {
      x = residual.segment(s, kSegment);
      x.array() -= x.mean();
      x -= tk * (tk.dot(x) / stt);
      for (int k = 0; k < kSegment; ++k) seg[static_cast<size_t>(k)] = x[k] * w[k];
      fft.fwd(spec, seg);
      for (size_t q = 0; q < nb; ++q)
        band[q] = 2.0 * std::norm(spec[static_cast<size_t>(bins[q])]) / (sample_rate_hz * w2);
      std::nth_element(band.begin(), band.begin() + static_cast<long>(nb / 2), band.end());
      levels.push_back(band[nb / 2] / median_mean);
      segments.emplace_back(s, kSegment);
      ++out.segments;
    }
  }
  if (out.segments == 0) return out;
  // Whether the segments' levels follow a channel: half-overlapping segments count half.
  const double effective = 0.5 * static_cast<double>(levels.size());
  if (effective >= 12) {
    std::tie(out.floor_channel, out.floor_correlation) = channel_ranking(
        levels, segments, channels, std::max(kMinRankCorr, 4.0 / std::sqrt(effective - 1)));
  }
  std::nth_element(levels.begin(), levels.begin() + static_cast<long>(levels.size() / 2),
                   levels.end());
  out.floor_nT = std::sqrt(levels[levels.size() / 2] * nyquist);
  out.computed = true;

  // The residual's local variance in windows against each channel's local mean (Spearman).
  const auto win = static_cast<Eigen::Index>(std::max(2.0, kWindow_s * sample_rate_hz));
  std::vector<std::pair<Eigen::Index, Eigen::Index>> windows;
  std::vector<double> local_var;
  for (const auto& [a, b] : runs) {
    for (Eigen::Index s = a; s + win <= b; s += win) {
      const auto r = residual.segment(s, win);
      windows.emplace_back(s, win);
      local_var.push_back((r.array() - r.mean()).square().mean());
    }
  }
  out.amplitude_windows = static_cast<int>(windows.size());
  if (windows.size() < 12) return out;
  // Significant: beyond 3 sigma of no correlation, and at least kMinRankCorr.
  std::tie(out.amplitude_channel, out.amplitude_correlation) = channel_ranking(
      local_var, windows, channels,
      std::max(kMinRankCorr, 3.0 / std::sqrt(static_cast<double>(windows.size()) - 1)));
  return out;
}

}  // namespace magcomp
