// magcomp: figure of merit.
#include "magcomp/core/evaluate/figure_of_merit.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "magcomp/core/evaluate/flight_conditions.h"
#include "magcomp/core/math/butterworth.h"
#include "magcomp/core/math/constants.h"

namespace magcomp {
namespace {

constexpr double kMinManeuver_s = 4.0;  // shorter oscillations are not a compensation maneuver

const char* heading4(double yaw_deg) {
  const double h = std::fmod(std::fmod(yaw_deg, 360.0) + 360.0 + 45.0, 360.0);
  static const char* names[4] = {"N", "E", "S", "W"};
  return names[static_cast<int>(h / 90.0) % 4];
}

// The series band-passed over the run [first, last] (zero-phase), NaN held at the nearest value.
Eigen::VectorXd band(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Index first,
                     Eigen::Index last, const Butterworth& bp) {
  Eigen::VectorXd seg = x.segment(first, last - first + 1);
  double hold = 0.0;
  bool any = false;
  for (Eigen::Index i = 0; i < seg.size(); ++i) {
    if (std::isfinite(seg[i])) {
      hold = seg[i];
      any = true;
    } else {
      seg[i] = hold;
    }
  }
  if (!any) return Eigen::VectorXd::Constant(seg.size(), NAN);
  return bp.filtfilt(seg);
}

double peak_to_peak(const Eigen::VectorXd& x, Eigen::Index a, Eigen::Index b) {
  const Eigen::VectorXd s = x.segment(a, b - a + 1);
  return s.maxCoeff() - s.minCoeff();
}

}  // namespace

FigureOfMerit figure_of_merit(const FlightData& data, const FitSettings& fit,
                              const Eigen::Ref<const Eigen::VectorXd>& compensated,
                              const Eigen::Ref<const Eigen::VectorXd>& uncompensated,
                              const std::vector<FlightCondition>* known_conditions) {
  FigureOfMerit out;
  const Eigen::Index n = data.size();
  if (n < 10 || !data.has("ins_yaw")) return out;
  std::vector<Eigen::Index> selected = data.select(fit.lines, fit.windows);
  out.where = selected.empty() ? "every sample" : "the model's calibration segments";
  if (selected.empty()) {
    selected.resize(static_cast<size_t>(n));
    for (Eigen::Index i = 0; i < n; ++i) selected[static_cast<size_t>(i)] = i;
  }
  const double dt = data.dt_s();
  std::vector<FlightCondition> classified;
  if (!known_conditions) classified = classify_conditions(data);
  const std::vector<FlightCondition>& conditions =
      known_conditions ? *known_conditions : classified;
  const auto yaw = data.column("ins_yaw");
  const Butterworth bp = Butterworth::band_pass(fit.order, fit.band_low_hz,
                                                std::min(fit.band_high_hz, 0.45 / dt), 1.0 / dt);
  // Maneuvers: contiguous runs of one maneuver condition inside the selected runs.
  struct Window {
    Eigen::Index first, last;
    int axis;
    std::string heading;
  };
  std::map<std::pair<int, std::string>, Window> best;
  for (const auto& [first, last] : data.contiguous_runs(selected, 1.5 * dt)) {
    Eigen::Index i = first;
    while (i <= last) {
      const auto c = conditions[static_cast<size_t>(i)];
      Eigen::Index j = i;
      while (j + 1 <= last && conditions[static_cast<size_t>(j + 1)] == c) ++j;
      const int axis = c == FlightCondition::kPitchManeuver  ? 0
                       : c == FlightCondition::kRollManeuver ? 1
                       : c == FlightCondition::kYawManeuver  ? 2
                                                             : -1;
      if (axis >= 0 && static_cast<double>(j - i) * dt >= kMinManeuver_s) {
        double sx = 0, sy = 0;
        for (Eigen::Index k = i; k <= j; ++k) {
          sx += std::cos(yaw[k] * kDegToRad);
          sy += std::sin(yaw[k] * kDegToRad);
        }
        const std::string h = heading4(std::atan2(sy, sx) * kRadToDeg);
        auto key = std::make_pair(axis, h);
        auto it = best.find(key);
        if (it == best.end() || j - i > it->second.last - it->second.first)
          best[key] = {i, j, axis, h};
      }
      i = j + 1;
    }
  }
  static const char* kAxes[3] = {"pitch", "roll", "yaw"};
  for (const auto& [key, w] : best) {
    // Band-pass over the whole contiguous run holding the maneuver, so the filter's edges stay
    // outside it.
    Eigen::Index a = w.first, b = w.last;
    while (a > 0 && std::abs(data.tt()[a] - data.tt()[a - 1]) < 1.5 * dt &&
           w.first - a < static_cast<Eigen::Index>(60.0 / dt))
      --a;
    while (b + 1 < n && std::abs(data.tt()[b + 1] - data.tt()[b]) < 1.5 * dt &&
           b - w.last < static_cast<Eigen::Index>(60.0 / dt))
      ++b;
    const Eigen::VectorXd c = band(compensated, a, b, bp);
    const Eigen::VectorXd u = band(uncompensated, a, b, bp);
    ManeuverSignature s;
    s.axis = kAxes[w.axis];
    s.heading = w.heading;
    s.start_tt_s = data.tt()[w.first];
    s.end_tt_s = data.tt()[w.last];
    s.peak_to_peak_nT = peak_to_peak(c, w.first - a, w.last - a);
    s.uncompensated_peak_to_peak_nT = peak_to_peak(u, w.first - a, w.last - a);
    out.fom_nT += s.peak_to_peak_nT;
    out.uncompensated_fom_nT += s.uncompensated_peak_to_peak_nT;
    out.signatures.push_back(s);
  }
  return out;
}

double fom_on_windows(const FlightData& data, const FitSettings& fit, const FigureOfMerit& fom,
                      const Eigen::VectorXd& series) {
  FigureOfMerit again = figure_of_merit(data, fit, series, series);
  double sum = 0;
  for (const auto& s : fom.signatures) {
    for (const auto& t : again.signatures) {
      if (t.axis == s.axis && t.heading == s.heading) sum += t.peak_to_peak_nT;
    }
  }
  return sum;
}

}  // namespace magcomp
