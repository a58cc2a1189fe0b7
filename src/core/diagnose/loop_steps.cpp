// magcomp: the steps the diagnose -> add -> refit loop is made of: scoring a model on the
// held-out lines of its flights, refusing it, the learned law of a channel, adding and removing
// terms, and the candidates a round may add (see loop_steps.h).
#include "loop_steps.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <set>

#include "magcomp/core/diagnose/diagnose_season.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {
namespace {

// Sum of squares and count of an error over the held-out samples of one half (-1: both), each
// line's mean (over those samples) removed.
std::pair<double, double> ss_on_fold(const Eigen::VectorXd& e, const HeldOut& h, int which) {
  std::map<double, std::pair<double, double>> mean;
  const Eigen::Index n = std::min<Eigen::Index>(e.size(), static_cast<Eigen::Index>(h.fold.size()));
  const auto in = [&](Eigen::Index i) {
    const int f = h.fold[static_cast<size_t>(i)];
    return f >= 0 && (which < 0 || f == which) && std::isfinite(e[i]);
  };
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!in(i)) continue;
    auto& a = mean[h.line[i]];
    a.first += e[i];
    a.second += 1;
  }
  double ss = 0, count = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!in(i)) continue;
    const auto& a = mean[h.line[i]];
    const double d = e[i] - a.first / a.second;
    ss += d * d;
    count += 1;
  }
  return {ss, count};
}

// Sum of squares of an error on each held-out line (both halves, each line's mean removed), in
// ascending line number.
std::vector<double> ss_per_line(const Eigen::VectorXd& e, const HeldOut& h) {
  std::map<double, std::array<double, 3>> sums;  // line -> sum, sum of squares, count
  const Eigen::Index n = std::min<Eigen::Index>(e.size(), static_cast<Eigen::Index>(h.fold.size()));
  for (Eigen::Index i = 0; i < n; ++i) {
    if (h.fold[static_cast<size_t>(i)] < 0 || !std::isfinite(e[i])) continue;
    auto& a = sums[h.line[i]];
    a[0] += e[i];
    a[1] += e[i] * e[i];
    a[2] += 1;
  }
  std::vector<double> out;
  for (const auto& [line, a] : sums) out.push_back(std::max(0.0, a[1] - a[0] * a[0] / a[2]));
  return out;
}

// Sum of squares and count of an error over `rows` (ascending), each contiguous segment's mean
// removed.
std::pair<double, double> ss_on_segments(const Eigen::VectorXd& e,
                                         const std::vector<Eigen::Index>& rows) {
  double ss = 0, count = 0;
  size_t k = 0;
  while (k < rows.size()) {
    size_t end = k + 1;
    while (end < rows.size() && rows[end] == rows[end - 1] + 1) ++end;
    double s = 0, s2 = 0, c = 0;
    for (size_t j = k; j < end; ++j) {
      const Eigen::Index i = rows[j];
      if (i >= e.size() || !std::isfinite(e[i])) continue;
      s += e[i];
      s2 += e[i] * e[i];
      c += 1;
    }
    if (c > 1) {
      ss += s2 - s * s / c;
      count += c;
    }
    k = end;
  }
  return {ss, count};
}

// The model whose slow terms are sized on the calibration rows and the held-out rows of half
// `h` (its lines' pieces) in place of fit.slow_lines.
Model sized_on_half(const Model& model, const std::vector<const FlightData*>& flights,
                    const std::vector<HeldOut>& held_out, int h) {
  std::vector<std::vector<Eigen::Index>> rows(flights.size());
  for (size_t f = 0; f < flights.size() && f < held_out.size(); ++f)
    for (size_t i = 0; i < held_out[f].fold.size(); ++i)
      if (held_out[f].fold[i] == h) rows[f].push_back(static_cast<Eigen::Index>(i));
  Model m = model;
  m.coefficients.resize(0);
  fit_model(m, flights, &rows);
  return m;
}

}  // namespace

// Scores of a model: held-out samples (both halves, and each), all lines, FOM, validation
// flight. Over several flights, each figure is pooled over the flights' samples (the FOM: their
// mean). Slow terms sized on held-out lines (fit.slow_lines) are cross-fitted: each half is
// scored with them sized on the other half's lines.
LoopRound score(const Model& model, const std::vector<const FlightData*>& flights,
                const std::string& truth, const std::vector<HeldOut>& held_out,
                const FlightData* validation) {
  LoopRound r;
  r.lambda = model.fit.lambda;
  double ss[3] = {0, 0, 0}, n[3] = {0, 0, 0};  // both halves, selection, confirmation
  double all_ss = 0, all_n = 0, fom_sum = 0, foms = 0, cal_ss = 0, cal_n = 0;
  std::optional<Model> for_half[2];  // sized on the other half's lines
  if (!model.slow_terms.empty() && !model.fit.slow_lines.empty())
    for (int h = 0; h < 2; ++h) for_half[h] = sized_on_half(model, flights, held_out, 1 - h);
  for (size_t f = 0; f < flights.size(); ++f) {
    const Evaluation ev = evaluate_model(model, *flights[f], truth, false);
    Eigen::VectorXd held_error = ev.error_nT;
    if (for_half[0]) {
      const Evaluation e0 = evaluate_model(*for_half[0], *flights[f], truth, false);
      const Evaluation e1 = evaluate_model(*for_half[1], *flights[f], truth, false);
      const HeldOut& ho = held_out[f];
      // Each half reads its sizes' correction about that correction's mean over every held-out
      // row: a channel's level (a bus at 27.5 V) read with two sizes would otherwise split a
      // line's pieces by a constant that the model, fitted once, never carries.
      const Eigen::VectorXd* half_error[2] = {&e0.error_nT, &e1.error_nT};
      double level[2] = {0, 0}, rows[2] = {0, 0};
      for (Eigen::Index i = 0; i < held_error.size(); ++i) {
        const int h = i < static_cast<Eigen::Index>(ho.fold.size()) ? ho.fold[i] : -1;
        for (int k = 0; h >= 0 && k < 2; ++k) {
          const double d = (*half_error[k])[i] - ev.error_nT[i];
          if (std::isfinite(d)) {
            level[k] += d;
            rows[k] += 1;
          }
        }
      }
      for (int k = 0; k < 2; ++k) level[k] = rows[k] > 0 ? level[k] / rows[k] : 0.0;
      for (Eigen::Index i = 0; i < held_error.size(); ++i) {
        const int h = i < static_cast<Eigen::Index>(ho.fold.size()) ? ho.fold[i] : -1;
        if (h >= 0) held_error[i] = (*half_error[h])[i] - level[h];
      }
    }
    if (!model.fit.lines.empty() || !model.fit.windows.empty()) {
      const auto [s, c] =
          ss_on_segments(ev.error_nT, flights[f]->select(model.fit.lines, model.fit.windows));
      cal_ss += s;
      cal_n += c;
    }
    double flight_ss = 0, flight_n = 0;
    for (int which = -1; which <= 1; ++which) {
      const auto [s, c] = ss_on_fold(held_error, held_out[f], which);
      ss[which + 1] += s;
      n[which + 1] += c;
      if (which < 0) {
        flight_ss = s;
        flight_n = c;
      }
    }
    r.flight_heldout_std_nT.push_back(flight_n > 0 ? std::sqrt(flight_ss / flight_n) : NAN);
    const std::vector<double> lines = ss_per_line(held_error, held_out[f]);
    r.line_ss_nT2.insert(r.line_ss_nT2.end(), lines.begin(), lines.end());
    all_ss += ev.std_nT * ev.std_nT * static_cast<double>(ev.n);
    all_n += static_cast<double>(ev.n);
    if (!ev.fom.signatures.empty()) {
      fom_sum += ev.fom.fom_nT;
      ++foms;
    }
  }
  const auto pooled = [](double s, double c) { return c > 0 ? std::sqrt(s / c) : NAN; };
  r.heldout_std_nT = pooled(ss[0], n[0]);
  if (n[1] > 0 && n[2] > 0) {
    r.selection_std_nT = pooled(ss[1], n[1]);
    r.confirmation_std_nT = pooled(ss[2], n[2]);
  }
  r.all_std_nT = pooled(all_ss, all_n);
  r.calibration_std_nT = pooled(cal_ss, cal_n);
  for (const TermSpec& t : model.terms)
    if (const ExprTerm* e = t.expr(); e && !e->required_fields().empty())
      r.channel_terms.push_back(t.text());
  r.fom_nT = foms > 0 ? fom_sum / foms : NAN;
  if (validation) r.validation_std_nT = evaluate_model(model, *validation, truth, false).std_nT;
  return r;
}

void take_scores(const LoopRound& scored, LoopRound* lr) {
  lr->heldout_std_nT = scored.heldout_std_nT;
  lr->selection_std_nT = scored.selection_std_nT;
  lr->confirmation_std_nT = scored.confirmation_std_nT;
  lr->all_std_nT = scored.all_std_nT;
  lr->calibration_std_nT = scored.calibration_std_nT;
  lr->flight_heldout_std_nT = scored.flight_heldout_std_nT;
  lr->line_ss_nT2 = scored.line_ss_nT2;
  lr->channel_terms = scored.channel_terms;
  lr->fom_nT = scored.fom_nT;
  lr->validation_std_nT = scored.validation_std_nT;
}

// The ridge strength chosen on the held-out samples (see loop_steps.h).
namespace {
// A change to the model as a whole (the ridge strength, TL's form), scored `lr` against `now`:
// kept when it lowers the held-out error on both halves, by the accepted share and the
// resolution, and `refusal` finds nothing against it.
bool passes_as_a_step(const LoopRound& lr, const LoopRound& now, const DiagnoseOptions& options) {
  const bool halves =
      !std::isfinite(now.selection_std_nT) || (lr.selection_std_nT < now.selection_std_nT &&
                                               lr.confirmation_std_nT < now.confirmation_std_nT);
  return halves && refusal(lr, now, options).empty() &&
         variance_share(lr.heldout_std_nT, now.heldout_std_nT) >= options.accept_fraction &&
         now.heldout_std_nT - lr.heldout_std_nT >= options.resolution_nT;
}
}  // namespace

std::optional<std::pair<Model, LoopRound>> better_lambda(
    const Model& model, double ceiling, const LoopRound& now,
    const std::vector<const FlightData*>& flights, const std::string& truth,
    const std::vector<HeldOut>& held_out, const FlightData* validation,
    const DiagnoseOptions& options) {
  if (!(ceiling > 0.0)) return std::nullopt;
  std::optional<std::pair<Model, LoopRound>> best;
  for (const double factor : {1.0, 1e-1, 1e-2, 1e-3}) {
    if (ceiling * factor == model.fit.lambda) continue;
    Model m = model;
    m.fit.lambda = ceiling * factor;
    m.coefficients.resize(0);
    try {
      fit_model(m, flights);
    } catch (const Error&) {
      continue;  // too weak a ridge for these columns: not a choice
    }
    LoopRound lr = score(m, flights, truth, held_out, validation);
    if (!std::isfinite(lr.heldout_std_nT)) continue;
    if (!best || lr.heldout_std_nT < best->second.heldout_std_nT)
      best.emplace(std::move(m), std::move(lr));
  }
  if (!best) return std::nullopt;
  const LoopRound& lr = best->second;
  if (!passes_as_a_step(lr, now, options)) return std::nullopt;
  return best;
}

std::vector<std::pair<Model, std::string>> exact_norm_forms(
    const Model& model, const std::vector<const FlightData*>& flights, const std::string& truth) {
  std::vector<std::pair<Model, std::string>> tries;
  if (std::find(model.terms.begin(), model.terms.end(), "norm") != model.terms.end()) return tries;
  {
    Model m = model;
    m.add_term(TermSpec("norm"));
    tries.emplace_back(std::move(m), "");
  }
  const bool reference_recorded =
      !truth.empty() && std::all_of(flights.begin(), flights.end(),
                                    [&](const FlightData* f) { return f->has(truth); });
  // Kept slow terms stay slow: the reference fit sizes the other columns on the calibration
  // rows and the slow ones after them, there and on fit.slow_lines, as the band-pass model did
  // (a drift of minutes barely moves on the calibration rows: sized there alone, it would lie
  // within the bias's span).
  if (model.fit.method == FitMethod::kBandpass && reference_recorded &&
      (model.slow_terms.empty() || model.fit.reference == truth)) {
    for (const double factor : {1.0, 1e-2}) {
      Model m = model;
      m.fit.method = FitMethod::kReference;
      m.fit.reference = truth;
      m.fit.lambda = model.fit.lambda * factor;
      if (m.slow_terms.empty()) m.fit.slow_lines.clear();
      m.add_term(TermSpec("bias"));
      m.add_term(TermSpec("norm"));
      char change[200];
      std::snprintf(change, sizeof(change), "fit.method reference (%s), fit.lambda %.3g",
                    truth.c_str(), m.fit.lambda);
      tries.emplace_back(std::move(m), change);
    }
  }
  return tries;
}

std::optional<std::pair<std::pair<Model, LoopRound>, std::string>> exact_norm_step(
    const Model& model, const LoopRound& now, const std::vector<const FlightData*>& flights,
    const std::string& truth, const std::vector<HeldOut>& held_out, const FlightData* validation,
    const DiagnoseOptions& options) {
  std::optional<std::pair<std::pair<Model, LoopRound>, std::string>> best;
  for (auto& [m, change] : exact_norm_forms(model, flights, truth)) {
    m.coefficients.resize(0);
    try {
      fit_model(m, flights);
    } catch (const Error&) {
      continue;  // not a fit these flights allow: not a choice
    }
    LoopRound lr = score(m, flights, truth, held_out, validation);
    if (!std::isfinite(lr.heldout_std_nT)) continue;
    if (!best || lr.heldout_std_nT < best->first.second.heldout_std_nT)
      best.emplace(std::make_pair(std::move(m), std::move(lr)), change);
  }
  if (!best) return std::nullopt;
  const LoopRound& lr = best->first.second;
  if (!passes_as_a_step(lr, now, options)) return std::nullopt;
  best->first.second.explained = variance_share(lr.heldout_std_nT, now.heldout_std_nT);
  return best;
}

std::string half_name(const LoopResult& r, size_t flights, int half) {
  const bool by_flight = std::any_of(r.rounds.begin(), r.rounds.end(),
                                     [](const LoopRound& lr) { return lr.flight_halves; });
  if (!by_flight || flights < 2) return half == 0 ? "the selection half" : "the confirmation half";
  std::string list;
  size_t count = 0;
  for (size_t f = half == 0 ? 0 : 1; f < flights; f += 2, ++count)
    list += (list.empty() ? "" : ", ") + std::to_string(f + 1);
  return (count == 1 ? "the held-out lines of flight " : "the held-out lines of flights ") + list;
}

// Why a scored candidate model is refused against the current one ("" when it is kept).
bool raises_calibration_rows(const LoopRound& next, const LoopRound& now, double resolution_nT) {
  constexpr double kCalibrationRiseFactor = 1.5;
  return std::isfinite(now.calibration_std_nT) && std::isfinite(next.calibration_std_nT) &&
         next.calibration_std_nT > kCalibrationRiseFactor * now.calibration_std_nT &&
         next.calibration_std_nT > now.calibration_std_nT + resolution_nT;
}

std::string refusal(const LoopRound& next, const LoopRound& now, const DiagnoseOptions& options) {
  char buf[256];
  if (!(next.heldout_std_nT < now.heldout_std_nT)) {
    std::snprintf(buf, sizeof(buf), "the held-out error would not fall (%.3f -> %.3f nT)",
                  now.heldout_std_nT, next.heldout_std_nT);
    return buf;
  }
  // A term of a channel sized by the band-pass must hold where it is sized: on the calibration
  // rows, at every frequency, it may not raise the error by half again and the resolution. A
  // stand-in (a channel whose band-passed columns happen to follow the residual on the
  // maneuvers) fits the band and adds its own low frequencies there; a true effect is on those
  // rows too. A term of the field itself (an eddy decay of B) is not held to it: its low
  // frequencies on the maneuvers are TL's own columns', which the band-pass leaves free too.
  const bool adds_channel_term =
      std::any_of(next.channel_terms.begin(), next.channel_terms.end(), [&](const std::string& t) {
        return std::find(now.channel_terms.begin(), now.channel_terms.end(), t) ==
               now.channel_terms.end();
      });
  if (options.check_calibration_rows && adds_channel_term &&
      raises_calibration_rows(next, now, options.resolution_nT)) {
    std::snprintf(buf, sizeof(buf),
                  "the error on the calibration rows it is fitted on would rise (%.3f -> %.3f nT, "
                  "unfiltered): its size does not hold where it is fitted",
                  now.calibration_std_nT, next.calibration_std_nT);
    return buf;
  }
  // With line_jackknife: the gain must hold without the held-out line where it is largest.
  if (options.line_jackknife && adds_channel_term && next.line_ss_nT2.size() > 2 &&
      next.line_ss_nT2.size() == now.line_ss_nT2.size()) {
    size_t best = 0;
    double now_rest = 0, next_rest = 0;
    for (size_t l = 0; l < now.line_ss_nT2.size(); ++l) {
      if (now.line_ss_nT2[l] - next.line_ss_nT2[l] > now.line_ss_nT2[best] - next.line_ss_nT2[best])
        best = l;
      now_rest += now.line_ss_nT2[l];
      next_rest += next.line_ss_nT2[l];
    }
    now_rest -= now.line_ss_nT2[best];
    next_rest -= next.line_ss_nT2[best];
    if (!(now_rest > 0) || 1.0 - next_rest / now_rest < options.accept_fraction) {
      std::snprintf(buf, sizeof(buf),
                    "without the held-out line where it gains most (%.1f%% of its gain), it "
                    "lowers the error variance of the other lines by %.1f%%, under %.0f%%",
                    100 * (now.line_ss_nT2[best] - next.line_ss_nT2[best]) /
                        std::max(1e-300, now.line_ss_nT2[best] + now_rest - next.line_ss_nT2[best] -
                                             next_rest),
                    now_rest > 0 ? 100 * (1.0 - next_rest / now_rest) : 0.0,
                    100 * options.accept_fraction);
      return buf;
    }
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
// when the channel is not a state of the aircraft (is_aircraft_state), barely moves on the
// calibration rows, or holds fewer than three distinct knots there (a two-level channel: a linear
// term says everything).
std::vector<TermSpec> learned_law(const std::string& channel, const Candidate* shape,
                                  const Model& model, const FlightData& data) {
  const ExprTerm* e = shape ? shape->term.expr() : nullptr;
  std::unique_ptr<ExprTerm> plain;
  if (!e || e->projection() == Projection::Induced) {
    plain = parse_expr_term("field:" + channel);
    e = plain.get();
  }
  // The aircraft's state channels only (is_aircraft_state): a residual that follows the
  // trajectory (velocities, heading, position) is leakage of the map or the reference, not a
  // law to learn.
  if (!is_aircraft_state(channel) || !data.has(channel)) return {};
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
  std::vector<TermSpec> law;
  for (double k : knots) {
    SignalExpr s;
    s.sources = {channel};
    s.transforms = {Transform{TransformKind::Ramp, std::stod(format_param(k)), false}};
    s.transforms.insert(s.transforms.end(), tail.begin(), tail.end());
    law.emplace_back(TermPtr(make_term(projection + s.str())));
  }
  return law;
}

// Adds a candidate's term to `m`; a slow one (Candidate::slow) joins Model::slow_terms, fitted
// against `truth` unless the model names its own reference.
void add_candidate_term(const TermSpec& term, bool slow, const std::string& truth, Model* m) {
  if (slow) {
    m->add_slow_term(term, truth);
    return;
  }
  m->add_term(term);
  auto& list = m->slow_terms;  // the same term fitted by the band-pass from now on
  list.erase(std::remove(list.begin(), list.end(), term), list.end());
}

// `m` without `term` (and out of its slow and black-box lists), unfitted.
Model without_term(const Model& m, const TermSpec& term) {
  Model out = m;
  out.terms.erase(std::remove(out.terms.begin(), out.terms.end(), term), out.terms.end());
  for (auto* list : {&out.slow_terms, &out.black_box_terms})
    list->erase(std::remove(list->begin(), list->end(), term), list->end());
  out.coefficients.resize(0);
  return out;
}

// True when `term` was added to `start` purely: adding it again to `start` grows it by one term
// (it replaced nothing of the start model: not a lag, not a re-estimated term of its shape).
bool removable(const Model& start, const TermSpec& term) {
  if (std::find(start.terms.begin(), start.terms.end(), term) != start.terms.end()) return false;
  // TL written as the exact norm (exact_norm_step) is TL's own form, not an added effect.
  if (term == "norm" || term == "bias") return false;
  Model probe = start;
  try {
    probe.add_term(term);
  } catch (const Error&) {
    return false;
  }
  return probe.terms.size() == start.terms.size() + 1;
}

bool revisable(const Model& start, const Model& model, const TermSpec& term, bool slow_too) {
  const auto listed = [&](const std::vector<std::string>& list) {
    return std::find(list.begin(), list.end(), term.text()) != list.end();
  };
  return removable(start, term) && !listed(model.black_box_terms) &&
         (slow_too || !listed(model.slow_terms));
}

// The share of `with`'s error variance that a change to `without` would add (negative when the
// change lowers the error).
double variance_share(double with_nT, double without_nT) {
  return 1.0 - std::pow(with_nT / without_nT, 2.0);
}

// The candidates of one round's diagnoses that the loop may add, in rank order (see
// diagnose_loop).
std::vector<Eligible> eligible_candidates(const std::vector<Diagnosis>& dxs, double min_share,
                                          bool within_span_too) {
  std::vector<Eligible> out;
  const auto ok = [&](const Candidate& c) {
    return c.accepted && c.explained_fraction >= min_share &&
           (within_span_too || !within_model_span(c.base_span_share));
  };
  if (dxs.size() == 1) {
    for (const Candidate& c : dxs.front().candidates)
      if (ok(c)) out.push_back({c.term, c.slow, c.explained_fraction, c.base_span_share});
    return out;
  }
  // Each shape's best passing form over the flights, then the flights' joint ranking.
  std::map<std::string, Eligible> best;
  for (const Diagnosis& d : dxs) {
    for (const Candidate& c : d.candidates) {
      if (!ok(c)) continue;
      auto [it, fresh] = best.emplace(
          term_shape(c.term), Eligible{c.term, c.slow, c.explained_fraction, c.base_span_share});
      if (!fresh && c.explained_fraction > it->second.explained)
        it->second = {c.term, c.slow, c.explained_fraction, c.base_span_share};
    }
  }
  for (const SeasonCandidate& s : merge_diagnoses(dxs).candidates) {
    const auto it = best.find(s.shape);
    if (it != best.end()) out.push_back(it->second);
  }
  return out;
}

// The recorded channels a term reads (none for a lag).
std::set<std::string> fields_of(const TermSpec& t) {
  const std::vector<std::string> f = t.term().required_fields();
  return std::set<std::string>(f.begin(), f.end());
}

std::set<std::string> fields_of(const Model& model) {
  std::set<std::string> out;
  for (const TermSpec& t : model.terms)
    for (const std::string& x : fields_of(t)) out.insert(x);
  return out;
}

// The terms of a round's step as LoopRound::added writes them (" + " joins a pair or a law).
std::vector<std::string> step_terms(const std::string& added) {
  std::vector<std::string> out;
  for (size_t from = 0;;) {
    const size_t to = added.find(" + ", from);
    out.push_back(added.substr(from, to == std::string::npos ? std::string::npos : to - from));
    if (to == std::string::npos) return out;
    from = to + 3;
  }
}

void record_displaced_lags(const Model& start, std::vector<LoopRound>* rounds) {
  const auto is_lag = [](const std::string& t) { return t.rfind("lag:", 0) == 0; };
  std::string in_force;  // the lag the model holds after each step
  for (const TermSpec& t : start.terms)
    if (is_lag(t.text())) in_force = t.text();
  for (LoopRound& lr : *rounds) {
    const auto names = [&](const std::vector<std::pair<std::string, std::string>>& list) {
      return std::any_of(list.begin(), list.end(), [&](const auto& e) {
        const std::vector<std::string> terms = step_terms(e.first);
        return std::find(terms.begin(), terms.end(), in_force) != terms.end();
      });
    };
    if (!in_force.empty() && (names(lr.removed) || names(lr.replaced))) in_force.clear();
    if (lr.added.empty()) continue;
    for (const std::string& t : step_terms(lr.added)) {
      if (!is_lag(t)) continue;
      if (!in_force.empty() && in_force != t) {
        lr.replaced.emplace_back(in_force,
                                 "its value estimated again with every other term in place (a "
                                 "model has one lag): " +
                                     t + " in its place");
      }
      in_force = t;
    }
    if (names(lr.removed)) in_force.clear();  // a step's own term may leave in its own row
  }
}

}  // namespace magcomp::loop_steps
