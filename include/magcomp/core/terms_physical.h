// magcomp: physical effects Tolles-Lawson does not model, as first-class terms.
#pragma once

#include "magcomp/core/term.h"

namespace magcomp {

/// A current-carrying source: its body-fixed field g·I (Biot-Savart, linear in the current I in A)
/// projected on the Earth-field direction. 3 columns B̂i·I (coefficients in nT/A).
/// With `rate` true, the inductive/eddy companion ∝ dI/dt: columns B̂i·dI/dt (dI/dt in A/s).
class CurrentTerm : public Term {
 public:
  CurrentTerm(std::string channel, bool rate) : channel_(std::move(channel)), rate_(rate) {}
  std::string spec() const override { return (rate_ ? "dcurrent:" : "current:") + channel_; }
  std::string effect() const override;
  std::vector<std::string> column_names() const override;
  std::vector<std::string> required_fields() const override { return {channel_}; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;

 private:
  std::string channel_;
  bool rate_;
};

/// A time lag between the scalar and the vector sensor: to first order the scalar reads
/// |B|(t - lag) = |B|(t) - lag·d|B|/dt. One column d|B|/dt in nT/s; its coefficient is -lag_s
/// (compensated = scalar - A c, so a positive coefficient means the scalar leads).
class LagTerm : public Term {
 public:
  std::string spec() const override { return "lag"; }
  std::string effect() const override {
    return "time lag between the scalar and vector sensors (coefficient = -lag in s)";
  }
  std::vector<std::string> column_names() const override { return {"lag.dBt_dt"}; }
  void build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const override;
};

}  // namespace magcomp
