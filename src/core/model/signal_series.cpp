// magcomp: a signal expression's transforms over a whole series (apply_transforms), one
// transform at a time with the arithmetic of the stream's stages (signal.cpp), bit for bit.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "magcomp/core/error.h"
#include "magcomp/core/model/signal.h"
#include "signal_pointwise.h"

namespace magcomp {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// One transform over a whole series, in place (t_s and x of n samples): the arithmetic of its
// stage in signal.cpp, sample by sample, without the per-sample calls of a chain. `tmp` is scratch
// of n.
void transform_series(const Transform& tr, const double* t, double* x, Eigen::Index n,
                      double* tmp) {
  switch (tr.kind) {
    case TransformKind::Derivative: {  // DerivativeStage: sample k's output, at t[k]
      if (n == 0) return;
      if (n == 1) {
        x[0] = 0.0;
        return;
      }
      std::copy(x, x + n, tmp);
      x[0] = (tmp[1] - tmp[0]) / (t[1] - t[0]);
      for (Eigen::Index k = 1; k + 1 < n; ++k)
        x[k] = (tmp[k + 1] - tmp[k - 1]) / (t[k + 1] - t[k - 1]);
      x[n - 1] = (tmp[n - 1] - tmp[n - 2]) / (t[n - 1] - t[n - 2]);
      return;
    }
    case TransformKind::Integral: {  // IntegralStage
      bool init = false;
      double acc = 0, xp = 0, tp = 0;
      for (Eigen::Index k = 0; k < n; ++k) {
        const double v = x[k];
        if (!std::isfinite(v)) {
          x[k] = kNaN;
          continue;
        }
        if (!init) {
          acc = 0.0;
          init = true;
        } else {
          acc += 0.5 * (v + xp) * (t[k] - tp);
        }
        xp = v;
        tp = t[k];
        x[k] = acc;
      }
      return;
    }
    case TransformKind::LowPass:
    case TransformKind::HighPass: {  // LowPassStage
      const bool high = tr.kind == TransformKind::HighPass;
      const double tau = tr.param;
      bool init = false;
      double s = 0, tp = 0;
      // The factors of the last few steps: a time base written as t0 + k dt rounds its steps to
      // a few values, between which the stage's one-step memory would call exp at every sample.
      // The same step gives the same factor, so the values are the stage's.
      constexpr int kSteps = 4;
      double step_s[kSteps] = {kNaN, kNaN, kNaN, kNaN}, factor[kSteps] = {1, 1, 1, 1};
      int next_slot = 0;
      for (Eigen::Index k = 0; k < n; ++k) {
        const double v = x[k];
        if (!std::isfinite(v)) {
          x[k] = kNaN;
          continue;
        }
        if (!init) {
          s = v;
          init = true;
        } else {
          const double dt = t[k] - tp;
          int slot = 0;
          while (slot < kSteps && !(step_s[slot] == dt)) ++slot;
          if (slot == kSteps) {
            slot = next_slot;
            next_slot = (next_slot + 1) % kSteps;
            step_s[slot] = dt;
            factor[slot] = std::exp(-dt / tau);
          }
          const double a = factor[slot];
          s = a * s + (1 - a) * v;
        }
        tp = t[k];
        x[k] = high ? v - s : s;
      }
      return;
    }
    case TransformKind::Decay: {  // d, then lp
      Transform d{TransformKind::Derivative, 0.0, false};
      Transform lp{TransformKind::LowPass, tr.param, false};
      transform_series(d, t, x, n, tmp);
      transform_series(lp, t, x, n, tmp);
      return;
    }
    case TransformKind::Play: {  // PlayStage
      const double r = tr.param;
      bool init = false;
      double s = 0;
      for (Eigen::Index k = 0; k < n; ++k) {
        const double v = x[k];
        if (!std::isfinite(v)) {
          x[k] = kNaN;
          continue;
        }
        s = init ? std::max(v - r, std::min(v + r, s)) : v;
        init = true;
        x[k] = s;
      }
      return;
    }
    case TransformKind::Delay: {  // DelayStage: the samples from `j` on are its history
      const double delay = tr.param;
      if (delay == 0.0) return;
      std::copy(x, x + n, tmp);
      Eigen::Index j = 0;
      for (Eigen::Index k = 0; k < n; ++k) {
        const double q = t[k] - delay;
        while (j + 1 <= k && t[j + 1] <= q) ++j;
        if (q <= t[j]) {
          x[k] = tmp[j];
        } else {
          x[k] = tmp[j] + (tmp[j + 1] - tmp[j]) * ((q - t[j]) / (t[j + 1] - t[j]));
        }
      }
      return;
    }
    case TransformKind::Abs:
    case TransformKind::Power:
    case TransformKind::Saturate:
    case TransformKind::Step:
    case TransformKind::Ramp: {  // PointwiseStage
      const PointwiseLaw law(tr.kind, tr.param);
      for (Eigen::Index k = 0; k < n; ++k) x[k] = law(x[k]);
      return;
    }
  }
}

}  // namespace

Eigen::MatrixXd apply_transforms(const std::vector<Transform>& transforms,
                                 const Eigen::Ref<const Eigen::VectorXd>& t_s,
                                 const Eigen::MatrixXd& x) {
  if (transforms.empty()) return x;
  for (const auto& tr : transforms)
    if (tr.free) throw Error("signal: transform '" + tr.str() + "' has no value yet");
  // Transform by transform over each column: each stage maps sample k at t[k] to sample k at
  // t[k] (a derivative looks one ahead, a delay back), so the composition is the chain's.
  if (t_s.size() < x.rows()) throw Error("signal: the time base is shorter than the series");
  Eigen::MatrixXd y = x;
  std::vector<double> tmp(static_cast<size_t>(x.rows()));
  for (Eigen::Index c = 0; c < y.cols(); ++c)
    for (const auto& tr : transforms)
      transform_series(tr, t_s.data(), y.col(c).data(), y.rows(), tmp.data());
  return y;
}

}  // namespace magcomp
