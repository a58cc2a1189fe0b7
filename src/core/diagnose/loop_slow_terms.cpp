// magcomp: the loop's slow terms revisited (internal to src/core/diagnose): a kept slow term's
// time constant estimated again, and a band-pass term slower than the band moved to the slow
// stage. Round::refine_parameters (loop_revisit.cpp) judges both.
#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "loop_round.h"
#include "magcomp/core/error.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {

std::vector<double> lines_beside_calibration(const FitSettings& fit,
                                             const std::vector<const FlightData*>& flights) {
  std::set<double> lines;
  for (const FlightData* f : flights) {
    if (!f->has("line")) continue;
    const std::vector<Eigen::Index> cal = f->select(fit.lines, fit.windows);
    std::vector<bool> in_cal(static_cast<size_t>(f->size()), false);
    for (Eigen::Index i : cal) in_cal[static_cast<size_t>(i)] = true;
    const auto line = f->column("line");
    for (Eigen::Index i = 0; i < line.size(); ++i)
      if (!in_cal[static_cast<size_t>(i)] && std::isfinite(line[i])) lines.insert(line[i]);
  }
  return {lines.begin(), lines.end()};
}

bool low_pass_below_band(const TermSpec& t, double band_low_hz) {
  const double tau_s = slowest_low_pass_s(t);
  return tau_s > 0 && 1.0 / (2 * M_PI * tau_s) < band_low_hz;
}

bool low_pass_beyond(const TermSpec& t, double tau_s) {
  const double slowest_s = slowest_low_pass_s(t);
  return slowest_s > 0 && slowest_s >= tau_s;
}

bool slow_form_of(const Model& model, size_t k, const Model& start, bool lines_size) {
  const TermSpec& t = model.terms[k];
  const bool sized_by_fit = model.fit.method == FitMethod::kBandpass ||
                            (lines_size && model.fit.method == FitMethod::kReference);
  if (!sized_by_fit || !revisable(start, model, t)) return false;
  const std::set<std::string> fields = fields_of(t);
  if (fields.empty() || !std::all_of(fields.begin(), fields.end(), is_aircraft_state)) return false;
  const ExprTerm* e = t.expr();
  if (!e || e->signal().has_free()) return false;
  // A reference fit sees the column unfiltered already: only the lines beside the calibration
  // rows add what the slow stage sizes it on, a heater's time constant or more.
  return model.fit.method == FitMethod::kReference ? low_pass_beyond(t, kSlowOnLinesMin_s)
                                                   : low_pass_below_band(t, model.fit.band_low_hz);
}

bool Round::moves_to_slow_stage(const LoopRound& lr, const LoopRound& now) const {
  const double accept = c_.options.accept_fraction;
  return refusal(lr, now, c_.options).empty() &&
         variance_share(lr.calibration_std_nT, now.calibration_std_nT) >= accept &&
         variance_share(lr.heldout_std_nT, now.heldout_std_nT) >= accept &&
         !passes(now.selection_std_nT, lr.selection_std_nT) &&
         !passes(now.confirmation_std_nT, lr.confirmation_std_nT);
}

std::string Round::retimed_slow_term(const Model& model, size_t k) const {
  const ExprTerm* e = model.terms[k].expr();
  if (!e) return "";
  const auto& chain = e->signal().transforms;
  size_t lp = chain.size();
  for (size_t j = 0; j < chain.size(); ++j) {
    if (chain[j].free) return "";
    if (chain[j].kind == TransformKind::LowPass) {
      if (lp < chain.size()) return "";  // two low-passes: not one time constant
      lp = j;
    }
  }
  if (lp == chain.size() || !(chain[lp].param > 0)) return "";
  const double tau0_s = chain[lp].param;
  // The term's shape (every parameter '?' but a ramp's knot) with its own parameters back and
  // tau_s in the low-pass's place.
  const TermSpec shape(e->shape());
  const ExprTerm* free = shape.expr();
  if (!free) return "";
  const auto spec_with = [&](double tau_s) {
    std::vector<double> values;
    for (const Transform& x : chain)
      if (x.has_param() && x.kind != TransformKind::Ramp)
        values.push_back(&x == &chain[lp] ? tau_s : x.param);
    return free->with_parameters(values);
  };
  // The calibration rows' error with the time constant tau_s, nT (infinite where the fit fails).
  const auto calibration_nT = [&](double tau_s) {
    try {
      const double nT = fit_score(with_term_as(model, model.terms[k].text(), spec_with(tau_s)))
                            .second.calibration_std_nT;
      return std::isfinite(nT) ? nT : std::numeric_limits<double>::infinity();
    } catch (const Error&) {
      return std::numeric_limits<double>::infinity();
    }
  };
  // The grid within a factor kSlowRetimeRange either way, then golden section in log(tau)
  // between the best point's neighbours (scan_parameter; three significant digits).
  std::vector<double> grid;
  for (int j = -kSlowRetimeSteps; j <= kSlowRetimeSteps; ++j)
    grid.push_back(tau0_s * std::pow(kSlowRetimeRange, static_cast<double>(j) / kSlowRetimeSteps));
  double best_nT = NAN;
  const double tau_s = scan_parameter(TransformKind::LowPass, grid, calibration_nT, &best_nT);
  if (!(tau_s > 0) || std::abs(std::log(tau_s / tau0_s)) < kSlowRetimeTolerance) return "";
  if (!(best_nT < calibration_nT(tau0_s))) return "";
  const std::string spec = spec_with(tau_s);
  return spec == model.terms[k].text() ? "" : spec;
}

}  // namespace magcomp::loop_steps
