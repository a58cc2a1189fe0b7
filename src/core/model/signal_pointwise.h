// magcomp: the static laws of a signal expression (abs, sat, step, ramp, pow) on one value,
// shared by the stream's stage (signal.cpp) and the batch over a series (signal_series.cpp), so
// that both give the same bits. Internal to src/core/model.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "magcomp/core/model/signal.h"

namespace magcomp {

// One static law with its parameter (unit of the signal; an exponent for pow).
struct PointwiseLaw {
  PointwiseLaw(TransformKind k, double p)
      : kind(k),
        param(p),
        integer(std::abs(p - std::round(p)) < 1e-12),
        square(integer && std::round(p) == 2.0) {}
  // The law at x (NaN passes).
  double operator()(double x) const {
    constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
    switch (kind) {
      case TransformKind::Abs:
        return std::abs(x);
      case TransformKind::Saturate:
        return param * std::tanh(x / param);
      case TransformKind::Step:
        return std::isfinite(x) ? (x > param ? 1.0 : 0.0) : kNaN;
      case TransformKind::Ramp:
        return std::isfinite(x) ? std::max(x - param, 0.0) : kNaN;
      default:
        // x * x is pow(x, 2) exactly (one rounding either way), and the commonest law.
        return square    ? x * x
               : integer ? std::pow(x, std::round(param))
                         : std::pow(std::abs(x), param);
    }
  }
  TransformKind kind;
  double param;
  bool integer;
  bool square;
};

}  // namespace magcomp
