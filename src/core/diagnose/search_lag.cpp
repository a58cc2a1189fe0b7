// magcomp: diagnose's scalar lag: its scan, alone or with the channel term whose timing it
// explains, and the lag candidate (see search.h).
#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <future>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

Eigen::MatrixXd Search::stacked_at_lag(const Eigen::MatrixXd& cols, double tau) const {
  const double lag_samples = tau / dt;
  const Eigen::Index reach = lag_round_trip_slice_margin(lag_samples), n = data.size();
  // Each run with `reach` rows each side: its rows get the same numbers as on the whole flight
  // (with fewer, a fractional lag of more than a sample gives the last rows of each run the
  // slice's held end, and the band-pass spreads that back over the run), and the rest of the
  // flight is never copied.
  Eigen::Index rows = 0;
  for (const auto& [first, last] : runs)
    rows += std::min(n - 1, last + reach) - std::max<Eigen::Index>(0, first - reach) + 1;
  Eigen::MatrixXd part(rows, cols.cols());
  std::vector<std::pair<Eigen::Index, Eigen::Index>> local;
  Eigen::Index r = 0;
  for (const auto& [first, last] : runs) {
    const Eigen::Index lo = std::max<Eigen::Index>(0, first - reach);
    const Eigen::Index len = std::min(n - 1, last + reach) - lo + 1;
    part.middleRows(r, len) = cols.middleRows(lo, len);
    lag_round_trip(part.middleRows(r, len), lag_samples);
    local.emplace_back(r + first - lo, r + last - lo);
    r += len;
  }
  part = part.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
  return stack_runs(fs, dt, part, local);
}

Eigen::MatrixXd Search::lag_columns(const Eigen::MatrixXd& partner) const {
  Model m = model;
  m.terms.erase(std::remove_if(m.terms.begin(), m.terms.end(),
                               [](const std::string& t) { return t.rfind("lag:", 0) == 0; }),
                m.terms.end());
  const auto terms = m.make_terms();
  const std::vector<Eigen::Index> keep = fittable_columns(fs.method, terms, model.slow_terms);
  const Eigen::Index p = static_cast<Eigen::Index>(keep.size());
  Eigen::MatrixXd x(data.size(), p + partner.cols());
  {
    const Eigen::MatrixXd a_all = design_matrix(m, terms, data);
    for (Eigen::Index k = 0; k < p; ++k) x.col(k) = a_all.col(keep[static_cast<size_t>(k)]);
  }
  x.rightCols(partner.cols()) = partner;
  return x;
}

double Search::lag_fit(double tau, const Eigen::MatrixXd& x, Eigen::VectorXd* coef) const {
  const Eigen::MatrixXd xf = stacked_at_lag(x, tau);
  const Eigen::MatrixXd g = xf.transpose() * xf;
  Eigen::MatrixXd r = g;
  r.diagonal().array() +=
      fs.lambda + 1e-12 * std::max(g.trace() / std::max<double>(g.cols(), 1), 1e-300);
  const FlightData::Column raw = data.column(model.scalar);
  const Eigen::VectorXd s_held = shift_samples(raw, -tau / dt, true);  // filters need no NaN
  const Eigen::VectorXd yl = fs.method == FitMethod::kBandpass
                                 ? s_held
                                 : Eigen::VectorXd(s_held - data.column(fs.reference));
  const Eigen::VectorXd ylf = stack_runs(fs, dt, yl, runs).col(0);
  *coef = r.ldlt().solve(xf.transpose() * ylf);
  return (ylf - xf * *coef).squaredNorm();
}

Scored Search::lag_candidate(double* tau_out, const Eigen::MatrixXd& partner) const {
  // Each trial realigns the raw scalar by tau (absolute) and gives the columns tau's round trip,
  // as a model with lag:tau does. Coarse grid over the model's lag +-1 s, then golden-section
  // refinement to 1 ms. A model that has a lag gets it re-estimated. With partner columns
  // (N x k) the lag is scanned and scored together with them: a lag moves the signature of every
  // effect, so it is judged with the term whose timing it explains.
  const double current = model.scalar_lag_s();
  Eigen::MatrixXd x = lag_columns(partner);
  // Estimated on the fit rows, as every free parameter is: the calibration maneuvers hold the
  // field rates that reveal a lag; the held-out lines (straight and level) barely do.
  Eigen::VectorXd coef;
  auto cost = [&](double tau) { return lag_fit(tau, x, &coef); };
  std::vector<double> grid;
  for (double tau = current - 1.0; tau <= current + 1.0 + 1e-9; tau += 0.05) grid.push_back(tau);
  // To the millisecond: at the field rates of a maneuver (tens of nT/s) 5 ms of lag error is
  // a fraction of a nT on the next flight.
  const double tau = std::round(scan_parameter(TransformKind::Delay, grid, cost) * 1000) / 1000;
  Scored s = lag_scored(tau, std::move(x), partner.cols());
  s.fits = static_cast<long>(grid.size()) + 26;
  *tau_out = tau;
  return s;
}

Scored Search::lag_at(double tau, const Eigen::MatrixXd& partner) const {
  return lag_scored(tau, lag_columns(partner), partner.cols());
}

Scored Search::lag_scored(double tau, Eigen::MatrixXd x, Eigen::Index partners) const {
  Eigen::VectorXd c;
  lag_fit(tau, x, &c);
  lag_round_trip(x, tau / dt);
  const Eigen::Index p = x.cols() - partners;
  // NaN past the ends; a partner without data gives no correction.
  Eigen::VectorXd e = shift_samples(data.column(model.scalar), -tau / dt) - truth -
                      x.leftCols(p) * c.head(p) - slow0;
  if (partners > 0) {
    e -= x.rightCols(partners).unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; }) *
         c.tail(partners);
  }
  Scored s;
  s.sel = fold_std(e, held, fold, line, 0);
  s.conf = fold_std(e, held, fold, line, 1);
  s.held = fold_std(e, held, fold, line, -1);
  s.ok = std::abs(tau - model.scalar_lag_s()) >= 0.005 && std::isfinite(s.sel) &&
         std::isfinite(s.conf) && std::isfinite(s.held) && c.allFinite();
  s.fits = 1;
  return s;
}

// A channel's term without a delay of its own (the partner a scalar lag is judged with).
TermSpec undelayed(const TermSpec& term) {
  const ExprTerm* e = term.expr();
  if (!e) return term;
  SignalExpr sig = e->signal();
  sig.transforms.erase(
      std::remove_if(sig.transforms.begin(), sig.transforms.end(),
                     [](const Transform& t) { return t.kind == TransformKind::Delay; }),
      sig.transforms.end());
  if (sig.transforms.empty() && sig.sources.size() == 1)
    return TermSpec(plain_spec(sig.sources[0]));
  return TermSpec(ExprTerm(e->projection(), sig).spec());
}

// The lag, alone; and, when the best candidate so far is a channel's term, together with that
// channel's term without a delay of its own: a scalar lag delays the channel's signature too,
// and the pair may explain more than the delayed term (round 1 adds the lag, round 2 the term).
void add_lag_candidate(const Model& model, const FlightData& data, const Search& search,
                       Diagnosis* dx) {
  double tau = 0;
  Scored lag = search.lag_candidate(&tau, Eigen::MatrixXd(data.size(), 0));
  dx->candidates_tried += lag.fits;
  double lag_pair_share = NAN;
  std::string partner_note;
  TermSpec partner_term;
  const Candidate* best = nullptr;
  for (const auto& c : dx->candidates) {
    if (!best || c.explained_selection > best->explained_selection) best = &c;
  }
  if (best && !best->channel.empty() && best->channel != model.scalar) {
    const TermSpec partner = undelayed(best->term);
    double tau2 = 0;
    const Scored pair = search.lag_candidate(&tau2, search.columns_of(partner.term(), false));
    dx->candidates_tried += pair.fits;
    const double pair_share = share(pair.sel, search.base_std[0]);
    if (pair.ok && pair_share > best->explained_selection + 0.01) {
      lag = search.lag_at(tau2, Eigen::MatrixXd(data.size(), 0));  // the lag by itself there
      tau = tau2;
      char buf[160];
      std::snprintf(buf, sizeof(buf), "; with %s next: %.1f%% together", partner.text().c_str(),
                    100 * pair_share);
      partner_note = buf;
      partner_term = partner;
      lag_pair_share = pair_share;
    }
  }
  if (!lag.ok) return;
  // The lag as its spec writes it (fewer digits than tau's): the model is given that text.
  const TermPtr term = make_term("lag:" + std::to_string(tau));
  Candidate c;
  c.term = TermSpec(term->spec());
  c.effect = term->effect();
  c.family = "scalar lag";
  c.std_after_nT = lag.held;
  c.explained_selection = share(lag.sel, search.base_std[0]);
  c.explained_confirmation = share(lag.conf, search.base_std[1]);
  std::ostringstream est;
  est.precision(3);
  est << "scalar late by " << tau << " s";
  if (model.scalar_lag_s() != 0.0) est << " (model: " << model.scalar_lag_s() << ")";
  c.estimate = est.str() + partner_note;
  c.parameters = {{"lag_s", tau}};
  c.ranking_share = std::isfinite(lag_pair_share) ? lag_pair_share : c.explained_selection;
  c.partner = partner_term;
  dx->candidates.push_back(c);
}

}  // namespace magcomp::diagnose_search
