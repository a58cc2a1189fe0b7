// magcomp: the steps the diagnose -> add -> refit loop is made of: scoring a model on the
// held-out lines of its flights, refusing it, the learned law of a channel, adding and removing
// terms, and the candidates a round may add (see loop_steps.h).
#include "loop_steps.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "magcomp/core/diagnose/diagnose_season.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {
namespace {

// Sum of squares and count of an evaluation's error over the given lines (all lines when
// empty), line means removed.
std::pair<double, double> ss_on_lines(const Evaluation& ev, const std::vector<double>& lines) {
  if (lines.empty())
    return {ev.std_nT * ev.std_nT * static_cast<double>(ev.n), static_cast<double>(ev.n)};
  double ss = 0, n = 0;
  for (const auto& l : ev.per_line) {
    if (std::find(lines.begin(), lines.end(), l.line) == lines.end()) continue;
    ss += l.std_nT * l.std_nT * static_cast<double>(l.n);
    n += static_cast<double>(l.n);
  }
  return {ss, n};
}

// Pooled std of an evaluation's error over the given lines (all lines when empty), nT.
double std_on_lines(const Evaluation& ev, const std::vector<double>& lines) {
  if (lines.empty()) return ev.std_nT;
  const auto [ss, n] = ss_on_lines(ev, lines);
  return n > 0 ? std::sqrt(ss / n) : ev.std_nT;
}

}  // namespace

// Scores of a model: held-out lines, all lines, FOM, validation flight. Over several flights,
// each figure is pooled over the flights' samples (the FOM: their mean).
LoopRound score(const Model& model, const std::vector<const FlightData*>& flights,
                const std::string& truth, const std::vector<HeldOut>& held_out,
                const FlightData* validation) {
  LoopRound r;
  if (flights.size() == 1) {
    const std::vector<double>& selection = held_out[0].selection;
    const std::vector<double>& confirmation = held_out[0].confirmation;
    const Evaluation ev = evaluate_model(model, *flights[0], truth, false);
    std::vector<double> held = selection;
    held.insert(held.end(), confirmation.begin(), confirmation.end());
    r.heldout_std_nT = std_on_lines(ev, held);
    if (!selection.empty() && !confirmation.empty()) {
      r.selection_std_nT = std_on_lines(ev, selection);
      r.confirmation_std_nT = std_on_lines(ev, confirmation);
    }
    r.all_std_nT = ev.std_nT;
    r.fom_nT = ev.fom.signatures.empty() ? NAN : ev.fom.fom_nT;
    r.flight_heldout_std_nT = {r.heldout_std_nT};
  } else {
    double held_ss = 0, held_n = 0, sel_ss = 0, sel_n = 0, conf_ss = 0, conf_n = 0, all_ss = 0,
           all_n = 0, fom_sum = 0, foms = 0;
    bool halves = true;
    for (size_t f = 0; f < flights.size(); ++f) {
      const Evaluation ev = evaluate_model(model, *flights[f], truth, false);
      const HeldOut& h = held_out[f];
      std::vector<double> held = h.selection;
      held.insert(held.end(), h.confirmation.begin(), h.confirmation.end());
      const auto [ss, n] = ss_on_lines(ev, held);
      held_ss += ss;
      held_n += n;
      r.flight_heldout_std_nT.push_back(n > 0 ? std::sqrt(ss / n) : NAN);
      halves = halves && !h.selection.empty() && !h.confirmation.empty();
      if (halves) {
        const auto [s1, n1] = ss_on_lines(ev, h.selection);
        const auto [s2, n2] = ss_on_lines(ev, h.confirmation);
        sel_ss += s1;
        sel_n += n1;
        conf_ss += s2;
        conf_n += n2;
      }
      const auto [a, na] = ss_on_lines(ev, {});
      all_ss += a;
      all_n += na;
      if (!ev.fom.signatures.empty()) {
        fom_sum += ev.fom.fom_nT;
        ++foms;
      }
    }
    r.heldout_std_nT = held_n > 0 ? std::sqrt(held_ss / held_n) : NAN;
    if (halves && sel_n > 0 && conf_n > 0) {
      r.selection_std_nT = std::sqrt(sel_ss / sel_n);
      r.confirmation_std_nT = std::sqrt(conf_ss / conf_n);
    }
    r.all_std_nT = all_n > 0 ? std::sqrt(all_ss / all_n) : NAN;
    r.fom_nT = foms > 0 ? fom_sum / foms : NAN;
  }
  if (validation) r.validation_std_nT = evaluate_model(model, *validation, truth, false).std_nT;
  return r;
}

// Why a scored candidate model is refused against the current one ("" when it is kept).
std::string refusal(const LoopRound& next, const LoopRound& now) {
  char buf[256];
  if (!(next.heldout_std_nT < now.heldout_std_nT)) {
    std::snprintf(buf, sizeof(buf), "the held-out error would not fall (%.3f -> %.3f nT)",
                  now.heldout_std_nT, next.heldout_std_nT);
    return buf;
  }
  if (std::isfinite(now.validation_std_nT) && !(next.validation_std_nT < now.validation_std_nT)) {
    std::snprintf(buf, sizeof(buf),
                  "the error on the validation flight would not fall (%.3f -> %.3f nT)",
                  now.validation_std_nT, next.validation_std_nT);
    return buf;
  }
  return "";
}

namespace {
bool linear(TransformKind k) {
  return k == TransformKind::Derivative || k == TransformKind::Integral ||
         k == TransformKind::LowPass || k == TransformKind::HighPass || k == TransformKind::Delay ||
         k == TransformKind::Decay;
}
}  // namespace

// A learned law of `channel`: hinges ramp(k) at its 1, 20, 40, 60 and 80 % quantiles on the
// model's calibration rows of this flight, each through the linear transforms of `shape` (the
// best ranked term of that channel, projected as it is; its static laws and its play dropped:
// the hinges stand for them). Their fitted sum is a piecewise-linear law of the channel, flat
// below its 1 % quantile, of which a closed form (|I|, I², tanh, a step) is one guess. Empty
// when the channel is not a current or a voltage, barely moves on the calibration rows, or holds
// fewer than three distinct knots there (a two-level channel: a linear term says everything).
std::vector<std::string> learned_law(const std::string& channel, const Candidate* shape,
                                     const Model& model, const FlightData& data) {
  std::unique_ptr<ExprTerm> e;
  if (shape) {
    try {
      e = parse_expr_term(shape->term);
    } catch (const Error&) {
    }
  }
  if (!e || e->projection() == Projection::Induced) e = parse_expr_term("field:" + channel);
  // Aircraft sources only (currents and voltages): a residual that follows the trajectory
  // (velocities, heading, position) is leakage of the map or the reference, not a law to learn.
  if (!is_electrical(channel) || !data.has(channel)) return {};
  // The knots where the fit sees the channel: its calibration rows (all rows for a fit without
  // a selection), so that no piece of the law rests on samples the fit never had; and the
  // calibration must see the channel move over at least a quarter of its 1-99 % range in flight.
  std::vector<Eigen::Index> rows;
  if (!model.fit.lines.empty() || !model.fit.windows.empty())
    rows = data.select(model.fit.lines, model.fit.windows);
  const auto x = data.column(channel);
  std::vector<double> v, all;
  for (Eigen::Index i = 0; i < x.size(); ++i)
    if (std::isfinite(x[i])) all.push_back(x[i]);
  for (Eigen::Index i : rows)
    if (std::isfinite(x[i])) v.push_back(x[i]);
  if (rows.empty()) v = all;
  if (v.size() < 100) return {};
  std::sort(v.begin(), v.end());
  std::sort(all.begin(), all.end());
  const auto quantile = [](const std::vector<double>& sorted, double q) {
    return sorted[static_cast<size_t>(q * static_cast<double>(sorted.size() - 1))];
  };
  const double span = quantile(v, 0.99) - quantile(v, 0.01);
  if (!(span > 0.25 * (quantile(all, 0.99) - quantile(all, 0.01)))) return {};
  // Knots closer than 5 % of that range are one knot: a two-level channel with noise on each
  // level gives no law between its levels.
  std::vector<double> knots;
  for (double q : {0.01, 0.2, 0.4, 0.6, 0.8}) {
    const double k = quantile(v, q);
    if (knots.empty() || k - knots.back() > 0.05 * span) knots.push_back(k);
  }
  if (knots.size() < 3) return {};
  // The tail: the term's linear transforms (d, int, lp, hp, delay, decay), in order; a sum of
  // hinges through linear transforms is the law through them.
  std::vector<Transform> tail;
  for (const Transform& t : e->signal().transforms)
    if (linear(t.kind)) tail.push_back(t);
  const char* projection = e->projection() == Projection::Field ? "field:" : "scalar:";
  std::vector<std::string> law;
  for (double k : knots) {
    SignalExpr s;
    s.sources = {channel};
    s.transforms = {Transform{TransformKind::Ramp, std::stod(format_param(k)), false}};
    s.transforms.insert(s.transforms.end(), tail.begin(), tail.end());
    law.push_back(make_term(projection + s.str())->spec());
  }
  return law;
}

// Adds a candidate's term to `m`; a slow one (Candidate::slow) joins Model::slow_terms, fitted
// against `truth` unless the model names its own reference.
void add_candidate_term(const std::string& term, bool slow, const std::string& truth, Model* m) {
  if (slow && m->fit.method == FitMethod::kBandpass) {
    m->add_slow_term(term, truth);
    return;
  }
  m->add_term(term);
  auto& list = m->slow_terms;  // the same term fitted by the band-pass from now on
  list.erase(std::remove(list.begin(), list.end(), term), list.end());
}

// `m` without `term` (and out of its slow and black-box lists), unfitted.
Model without_term(const Model& m, const std::string& term) {
  Model out = m;
  for (auto* list : {&out.terms, &out.slow_terms, &out.black_box_terms})
    list->erase(std::remove(list->begin(), list->end(), term), list->end());
  out.coefficients.resize(0);
  return out;
}

// True when `term` was added to `start` purely: adding it again to `start` grows it by one term
// (it replaced nothing of the start model: not a lag, not a re-estimated term of its shape).
bool removable(const Model& start, const std::string& term) {
  if (std::find(start.terms.begin(), start.terms.end(), term) != start.terms.end()) return false;
  Model probe = start;
  try {
    probe.add_term(term);
  } catch (const Error&) {
    return false;
  }
  return probe.terms.size() == start.terms.size() + 1;
}

// The share of `with`'s error variance that a change to `without` would add (negative when the
// change lowers the error).
double variance_share(double with_nT, double without_nT) {
  return 1.0 - std::pow(with_nT / without_nT, 2.0);
}

// The candidates of one round's diagnoses that the loop may add, in rank order (see
// diagnose_loop).
std::vector<Eligible> eligible_candidates(const std::vector<Diagnosis>& dxs, double min_share) {
  std::vector<Eligible> out;
  const auto ok = [&](const Candidate& c) {
    return c.accepted && c.explained_fraction >= min_share;
  };
  if (dxs.size() == 1) {
    for (const Candidate& c : dxs.front().candidates)
      if (ok(c)) out.push_back({c.term, c.slow, c.explained_fraction});
    return out;
  }
  // Each shape's best passing form over the flights, then the flights' joint ranking.
  std::map<std::string, Eligible> best;
  for (const Diagnosis& d : dxs) {
    for (const Candidate& c : d.candidates) {
      if (!ok(c)) continue;
      auto [it, fresh] =
          best.emplace(term_shape(c.term), Eligible{c.term, c.slow, c.explained_fraction});
      if (!fresh && c.explained_fraction > it->second.explained)
        it->second = {c.term, c.slow, c.explained_fraction};
    }
  }
  for (const SeasonCandidate& s : merge_diagnoses(dxs).candidates) {
    const auto it = best.find(s.shape);
    if (it != best.end()) out.push_back(it->second);
  }
  return out;
}

}  // namespace magcomp::loop_steps
