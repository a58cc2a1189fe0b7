// magcomp: the signal part of the term language: sources, their product, and causal transforms.
//
//   signal    := product ('|' transform)*
//   product   := source ('*' source)*          a data field, B (the vector sensor, 3 components,
//                                               nT) or Bt (its magnitude, nT)
//   transform := d | int | abs | lp(P) | hp(P) | delay(P) | pow(P) | decay(P) | play(P)
//              | sat(P) | step(P) | ramp(P)
//   P         := a number | ?                   ? = free: estimated by the fit
//
// Every transform runs as a causal recursion over the samples in time order (a derivative looks
// one sample ahead), and the batch evaluation runs the very same recursion over the whole flight,
// so a stream reproduces the batch result exactly.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

namespace magcomp {

/// The transforms a signal can pass through, in time order.
enum class TransformKind {
  Derivative,  ///< d: central difference per second (one-sided at both ends); 1 sample ahead
  Integral,    ///< int: running trapezoidal integral over s, from 0 at the stream's start
  Abs,         ///< abs: |x|
  LowPass,     ///< lp(tau_s): first-order low-pass, y' = (x - y) / tau
  HighPass,    ///< hp(tau_s): x - lp(tau_s)
  Delay,       ///< delay(s): x(t - s), linear interpolation, the first value before the start
  Power,       ///< pow(p): x^p for an integer p, |x|^p otherwise
  Decay,       ///< decay(tau_s): lp(tau_s) of d: a response to the rate that decays with tau
  /// play(r): the backlash (play) operator of half-width r, in the signal's unit: the output
  /// follows the input only once it has moved r past it, y = max(x - r, min(x + r, y_prev)),
  /// starting at the first input. Hysteresis; sums of them are the Prandtl-Ishlinskii model.
  Play,
  /// sat(s): a saturating core, y = s tanh(x / s), in the signal's unit: linear for |x| << s,
  /// levelling off at +-s (a static nonlinearity; stream = batch, nothing held).
  Saturate,
  /// step(x0): a switched load, y = 1 while x > x0, else 0 (a relay on the signal's level).
  Step,
  /// ramp(x0): a hinge, y = max(x - x0, 0), in the signal's unit. A sum of hinges at several
  /// knots is a piecewise-linear law of the signal that no formula names (diagnose's learned law).
  Ramp,
};

/// A transform and its parameter (time constant or delay in s, or an exponent).
struct Transform {
  TransformKind kind = TransformKind::Abs;
  double param = 0.0;  ///< unused for d, int, abs
  bool free = false;   ///< the parameter is '?': to be estimated by the fit

  bool has_param() const;
  /// "d", "lp(12.5)", "lp(?)".
  std::string str() const;
  /// The parameter's name and unit in words, e.g. "time constant (s)".
  std::string param_meaning() const;
};

/// A product of sources passed through transforms.
struct SignalExpr {
  std::vector<std::string> sources;
  std::vector<Transform> transforms;

  /// The canonical text (what parse_signal reads back).
  std::string str() const;
  /// True when a transform's parameter is '?'.
  bool has_free() const;
  /// Samples the signal needs after a sample before its value there is known (derivatives).
  int lookahead() const;
  /// Number of components: 3 when B is among the sources, else 1.
  int width() const;
};

/// Parses the signal grammar above. `context` (e.g. the whole term) goes into the one-line error.
SignalExpr parse_signal(const std::string& text, const std::string& context);

/// Formats a parameter value for a spec: %g with 6 significant digits.
std::string format_param(double value);

/// One stage of a causal transform chain: takes samples in time order, returns outputs in order.
class SignalStage {
 public:
  virtual ~SignalStage() = default;
  /// Takes (t_s, x); returns true and sets (*t_out, *y) when an output is ready.
  virtual bool push(double t_s, double x, double* t_out, double* y) = 0;
  /// End of the stream: returns true and sets the last pending output, if any.
  virtual bool flush(double* /*t_out*/, double* /*y*/) { return false; }
  virtual void reset() = 0;
};

/// The transforms of one signal component as a chain of stages (a decay is two).
class TransformChain {
 public:
  explicit TransformChain(const std::vector<Transform>& transforms);
  TransformChain(const TransformChain&) = delete;
  TransformChain& operator=(const TransformChain&) = delete;
  /// Feeds one sample; calls emit(t_s, y) for every output that became ready (in order).
  template <typename Emit>
  void push(double t_s, double x, Emit&& emit) {
    feed(0, t_s, x, emit);
  }
  /// End of stream: emits what the look-ahead stages still hold, then starts afresh.
  template <typename Emit>
  void flush(Emit&& emit) {
    for (size_t k = 0; k < stages_.size(); ++k) {
      double t, y;
      if (stages_[k]->flush(&t, &y)) feed(k + 1, t, y, emit);
    }
    reset();
  }
  void reset();

 private:
  template <typename Emit>
  void feed(size_t k, double t_s, double x, Emit& emit) {
    for (; k < stages_.size(); ++k) {
      if (!stages_[k]->push(t_s, x, &t_s, &x)) return;
    }
    emit(t_s, x);
  }
  std::vector<std::unique_ptr<SignalStage>> stages_;
};

/// Runs the transforms over a whole series (time t_s, values x: N x width, NaN kept) with the
/// same recursion a TransformChain runs on a stream. Returns N x width.
Eigen::MatrixXd apply_transforms(const std::vector<Transform>& transforms,
                                 const Eigen::Ref<const Eigen::VectorXd>& t_s,
                                 const Eigen::MatrixXd& x);

}  // namespace magcomp
