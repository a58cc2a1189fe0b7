// magcomp: Butterworth IIR filters as second-order sections; zero-phase batch and causal streaming.
#pragma once

#include <Eigen/Core>
#include <array>
#include <vector>

namespace magcomp {

/// One biquad, normalised so that a0 = 1: y = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2) x.
struct Biquad {
  std::array<double, 3> b{{1.0, 0.0, 0.0}};
  std::array<double, 3> a{{1.0, 0.0, 0.0}};
};

enum class FilterType { kLowPass, kHighPass, kBandPass };

/// A digital Butterworth filter designed by the bilinear transform with pre-warping.
/// Cut-off frequencies in Hz, sample rate in Hz. `order` is the prototype order (a band-pass of
/// order n has 2n poles, as in scipy/DSP.jl). Gain is exactly 1 at DC (low-pass), Nyquist
/// (high-pass) or the geometric centre of the band (band-pass).
class Butterworth {
 public:
  /// Throws magcomp::Error naming the parameter when cut-offs are outside (0, fs/2) or order < 1.
  Butterworth(FilterType type, int order, double low_hz, double high_hz, double sample_rate_hz);

  static Butterworth low_pass(int order, double cutoff_hz, double sample_rate_hz);
  static Butterworth high_pass(int order, double cutoff_hz, double sample_rate_hz);
  static Butterworth band_pass(int order, double low_hz, double high_hz, double sample_rate_hz);

  const std::vector<Biquad>& sections() const { return sections_; }
  double sample_rate_hz() const { return sample_rate_hz_; }
  /// |H| at frequency f_hz (for checks: -3 dB = 1/sqrt(2) at the cut-offs).
  double magnitude(double f_hz) const;

  /// Zero-phase forward-backward filtering with odd-reflection edge padding and steady-state
  /// initial conditions (the scipy sosfiltfilt scheme). NaN in the input propagates; callers
  /// filter finite segments. Padding length is min(3 * (2 * sections + 1), n - 1).
  Eigen::VectorXd filtfilt(const Eigen::VectorXd& x) const;
  /// Column-wise filtfilt of a matrix (all columns in one vectorised pass).
  Eigen::MatrixXd filtfilt(const Eigen::Ref<const Eigen::MatrixXd>& x) const;
  /// The same, with the columns split over `threads` threads (for large blocks).
  Eigen::MatrixXd filtfilt_parallel(const Eigen::Ref<const Eigen::MatrixXd>& x, int threads) const;
  /// Causal single-pass filtering from steady state at x[0].
  Eigen::VectorXd filter(const Eigen::VectorXd& x) const;

  /// Steady-state initial state (direct form II transposed, 2 values per section) for a unit step.
  std::vector<std::array<double, 2>> step_state() const;

 private:
  std::vector<Biquad> sections_;
  double sample_rate_hz_ = 1.0;
};

/// Causal streaming form of a Butterworth filter: one sample in, one sample out (online path).
class StreamingFilter {
 public:
  explicit StreamingFilter(const Butterworth& filter);
  /// Filters one sample. The first sample initialises the state to steady state at its value.
  double step(double x);
  /// Forgets the state (e.g. after a time jump); the next sample re-initialises it.
  void reset() { primed_ = false; }

 private:
  std::vector<Biquad> sections_;
  std::vector<std::array<double, 2>> unit_state_;
  std::vector<std::array<double, 2>> state_;
  bool primed_ = false;
};

}  // namespace magcomp
