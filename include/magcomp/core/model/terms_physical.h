// magcomp: the second-order and exact-norm terms and the scalar lag (the term language is in
// terms_expr.h).
#pragma once

#include "magcomp/core/model/term.h"

namespace magcomp {

/// The dropped second-order term's part outside the TL span: with B_a = M B (induced), the
/// expansion of |B + B_a| has (|B_a|² - (B̂·B_a)²) / (2|B|), quartic in B̂. 15 columns
/// B̂iB̂jB̂kB̂l·|B| / Bt_scale (i <= j <= k <= l); the quadratic parts are already in `induced`.
class SecondOrderTerm : public Term {
 public:
  std::string spec() const override { return "second_order"; }
  std::string effect() const override {
    return "second-order (induced x induced) term dropped by the TL linearisation";
  }
  std::vector<std::string> column_names() const override;
  int row_reach() const override { return 0; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;
};

/// The exact norm: the scalar sensor reads |B + v|, v the aircraft's field as a vector, where TL
/// writes its first-order expansion |B| + B̂·v. One column, norm_remainder_nT() of the model's own
/// TL coefficients (permanent, induced*, eddy*): design_matrix() fills it from the fitted model,
/// and a fit iterates until the TL coefficients it is built from settle (fit_model). Its
/// coefficient is about 1. Zeros until the model's TL is fitted. `norm`.
class NormTerm : public Term {
 public:
  std::string spec() const override { return "norm"; }
  std::string effect() const override {
    return "the scalar as the exact norm of Earth's field plus TL's vector field (what TL's "
           "first-order expansion drops, from TL's own coefficients)";
  }
  std::vector<std::string> column_names() const override { return {"norm"}; }
  int row_reach() const override { return 1; }  // the eddy field's central difference
  void build(const TermInputs&, Eigen::Ref<Eigen::MatrixXd> out) const override {
    out.setZero();  // design_matrix() fills it from the model's coefficients
  }
};

/// A time lag between the scalar and the vector sensor: the scalar reads everything it measures
/// (Earth field, aircraft field, wires) lag_s late. Not a regression column: the model realigns
/// the scalar, s(t + lag_s), by cubic interpolation before fitting and compensating, and gives
/// every column the same delay-and-realign round trip (lag_round_trip, timeseries.h), since a
/// fractional realignment of a sampled record smooths what the sensor measured. `lag:0.3`.
class LagTerm : public Term {
 public:
  explicit LagTerm(double lag_s) : lag_s_(lag_s) {}
  std::string spec() const override;
  std::string effect() const override {
    return "time lag of the scalar sensor behind the vector sensor (realigned)";
  }
  std::vector<std::string> column_names() const override { return {}; }
  double scalar_lag_s() const override { return lag_s_; }
  int row_reach() const override { return 0; }
  void build(const TermInputs&, Eigen::Ref<Eigen::MatrixXd>) const override {}

 private:
  double lag_s_;
};

}  // namespace magcomp
