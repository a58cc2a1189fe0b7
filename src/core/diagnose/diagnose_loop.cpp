// magcomp: the diagnose -> add -> refit loop.
#include "magcomp/core/diagnose/diagnose_loop.h"
#include "magcomp/core/fit/model_fit.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {
namespace {

// Pooled std of an evaluation's error over the given lines (all lines when empty), nT.
double std_on_lines(const Evaluation& ev, const std::vector<double>& lines) {
  if (lines.empty()) return ev.std_nT;
  double ss = 0, n = 0;
  for (const auto& l : ev.per_line) {
    if (std::find(lines.begin(), lines.end(), l.line) == lines.end()) continue;
    ss += l.std_nT * l.std_nT * static_cast<double>(l.n);
    n += static_cast<double>(l.n);
  }
  return n > 0 ? std::sqrt(ss / n) : ev.std_nT;
}

// Scores of a model: held-out lines, all lines, FOM, validation flight.
LoopRound score(const Model& model, const FlightData& data, const std::string& truth,
                const std::vector<double>& selection, const std::vector<double>& confirmation,
                const FlightData* validation) {
  LoopRound r;
  const Evaluation ev = evaluate_model(model, data, truth, false);
  std::vector<double> held = selection;
  held.insert(held.end(), confirmation.begin(), confirmation.end());
  r.heldout_std_nT = std_on_lines(ev, held);
  if (!selection.empty() && !confirmation.empty()) {
    r.selection_std_nT = std_on_lines(ev, selection);
    r.confirmation_std_nT = std_on_lines(ev, confirmation);
  }
  r.all_std_nT = ev.std_nT;
  r.fom_nT = ev.fom.signatures.empty() ? NAN : ev.fom.fom_nT;
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

bool linear(TransformKind k) {
  return k == TransformKind::Derivative || k == TransformKind::Integral ||
         k == TransformKind::LowPass || k == TransformKind::HighPass || k == TransformKind::Delay ||
         k == TransformKind::Decay;
}

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
}  // namespace

LoopResult diagnose_loop(const Model& start, const FlightData& data, const std::string& truth,
                         int max_rounds, double min_share, const DiagnoseOptions& options,
                         const std::function<void(int, const Diagnosis&)>& on_round,
                         const FlightData* validation) {
  constexpr size_t kTriesPerRound = 3;
  std::set<std::string> learned_channels;  // one learned law per channel
  LoopResult r;
  r.model = start;
  if (!r.model.fitted()) fit_model(r.model, {&data});
  std::vector<double> selection, confirmation;  // the held-out lines, in two halves
  for (int round = 1;; ++round) {
    Diagnosis dx = diagnose(r.model, data, truth, options);
    if (round == 1) {
      selection = dx.selection_lines;
      confirmation = dx.confirmation_lines;
      r.rounds.push_back(score(r.model, data, truth, selection, confirmation, validation));
    }
    if (on_round) on_round(round, dx);
    // The candidates the loop may add, in rank order: accepted, and explaining at least
    // min_share on both halves (a term ranked first on the selection lines may explain little
    // on the confirmation lines, where the error may lie).
    std::vector<const Candidate*> eligible;
    for (const Candidate& c : dx.candidates) {
      if (c.accepted && c.explained_fraction >= min_share) eligible.push_back(&c);
    }
    if (round > max_rounds) {
      r.stop_reason = "stopped after " + std::to_string(max_rounds) + " rounds; " + dx.verdict;
      r.last = std::move(dx);
      break;
    }
    // Fits `next` and keeps it if it passes every check; else records why in `rejected`.
    std::vector<std::pair<std::string, std::string>> rejected;
    auto try_model = [&](Model next, const std::string& added, double explained, bool black_box) {
      next.coefficients.resize(0);
      fit_model(next, {&data});
      LoopRound lr = score(next, data, truth, selection, confirmation, validation);
      std::string why = refusal(lr, r.rounds.back());
      // A learned law has many columns: it must also explain the accepted share of the held-out
      // variance, as every candidate must on each split.
      const double share_left = std::pow(lr.heldout_std_nT / r.rounds.back().heldout_std_nT, 2.0);
      if (why.empty() && black_box && 1.0 - share_left < options.accept_fraction) {
        char buf[160];
        std::snprintf(buf, sizeof(buf),
                      "the held-out error would fall by less than %.0f%% of its variance "
                      "(%.3f -> %.3f nT)",
                      100 * options.accept_fraction, r.rounds.back().heldout_std_nT,
                      lr.heldout_std_nT);
        why = buf;
      }
      if (!why.empty()) {
        rejected.emplace_back(added, why);
        return false;
      }
      lr.round = round;
      lr.added = added;
      lr.explained = explained;
      lr.black_box = black_box;
      lr.rejected = std::move(rejected);
      rejected.clear();
      r.rounds.push_back(std::move(lr));
      r.model = std::move(next);
      return true;
    };
    auto fit_score = [&](Model m) {
      m.coefficients.resize(0);
      fit_model(m, {&data});
      LoopRound lr = score(m, data, truth, selection, confirmation, validation);
      return std::make_pair(std::move(m), std::move(lr));
    };
    // The accepted candidates in rank order: the first that passes every check is kept.
    bool kept = false;
    for (size_t k = 0; k < eligible.size() && k < kTriesPerRound && !kept; ++k) {
      Model next = r.model;
      add_candidate_term(eligible[k]->term, eligible[k]->slow, truth, &next);
      kept = try_model(std::move(next), eligible[k]->term, eligible[k]->explained_fraction, false);
    }
    // Effects that act together: when no term passes alone while the residual stays
    // predictable, pairs of terms of distinct channels, fitted together. A pair is kept if it
    // passes every check, lowers the error on each half of the held-out lines by the accepted
    // share and the resolution, and each of its terms lowers the pair's error variance by the
    // accepted share (each is needed); at least one of them must fail alone (else it is the
    // single step's business). The best such pair by held-out error.
    const ExplainableShare& ex0 = dx.explainable;
    if (options.joint_steps && !kept && !ex0.within_noise) {
      // The pool: for each of the three channels that predict most of the residual (and that
      // the search gives terms of), its plain term and its first ranked term, whatever their
      // share alone: effects that cancel one another show in the residual's channels, not in
      // each term's share.
      constexpr size_t kResidualChannels = 3;
      std::vector<Candidate> pool;
      std::set<std::string> in_pool;
      const auto take = [&](const Candidate& c) {
        if (in_pool.insert(c.term).second) pool.push_back(c);
      };
      for (size_t k = 0; k < ex0.channels.size() && k < kResidualChannels; ++k) {
        const std::string& channel = ex0.channels[k].first;
        const auto first = std::find_if(dx.candidates.begin(), dx.candidates.end(),
                                        [&](const Candidate& c) { return c.channel == channel; });
        if (first == dx.candidates.end()) continue;
        Candidate plain;
        plain.term = (is_electrical(channel) ? "current:" : "field:") + channel;
        plain.channel = channel;
        take(plain);
        take(*first);
      }
      std::vector<LoopRound> alone(pool.size());
      for (size_t a = 0; a < pool.size(); ++a) {
        alone[a].heldout_std_nT = NAN;  // a term that cannot be fitted here is left out
        try {
          Model next = r.model;
          add_candidate_term(pool[a].term, pool[a].slow, truth, &next);
          alone[a] = fit_score(std::move(next)).second;
        } catch (const Error&) {
        }
      }
      const LoopRound& now = r.rounds.back();
      double best_std = INFINITY;
      std::optional<std::pair<Model, LoopRound>> best;
      size_t best_a = 0, best_b = 0;
      for (size_t a = 0; a < pool.size(); ++a) {
        for (size_t b = a + 1; b < pool.size(); ++b) {
          if (pool[a].channel == pool[b].channel || !std::isfinite(alone[a].heldout_std_nT) ||
              !std::isfinite(alone[b].heldout_std_nT))
            continue;
          if (refusal(alone[a], now).empty() && refusal(alone[b], now).empty())
            continue;  // both lower the error alone: not a pair that only acts together
          Model next = r.model;
          add_candidate_term(pool[a].term, pool[a].slow, truth, &next);
          add_candidate_term(pool[b].term, pool[b].slow, truth, &next);
          auto [fitted, lr] = fit_score(std::move(next));
          if (!refusal(lr, now).empty()) continue;
          // On each half of the held-out lines, as a term of the search is accepted on each
          // split: the accepted share of the variance and the resolution of the std.
          const auto passes = [&](double with_nT, double without_nT) {
            return variance_share(with_nT, without_nT) >= options.accept_fraction &&
                   without_nT - with_nT >= options.resolution_nT;
          };
          if (!passes(lr.selection_std_nT, now.selection_std_nT) ||
              !passes(lr.confirmation_std_nT, now.confirmation_std_nT))
            continue;
          if (variance_share(lr.heldout_std_nT, alone[a].heldout_std_nT) <
                  options.accept_fraction ||
              variance_share(lr.heldout_std_nT, alone[b].heldout_std_nT) < options.accept_fraction)
            continue;
          if (lr.heldout_std_nT < best_std) {
            best_std = lr.heldout_std_nT;
            best.emplace(std::move(fitted), std::move(lr));
            best_a = a;
            best_b = b;
          }
        }
      }
      if (best) {
        LoopRound lr = std::move(best->second);
        lr.round = round;
        lr.added = pool[best_a].term + " + " + pool[best_b].term;
        lr.explained = variance_share(lr.heldout_std_nT, now.heldout_std_nT);
        lr.together = true;
        lr.alone_std_nT = {alone[best_a].heldout_std_nT, alone[best_b].heldout_std_nT};
        lr.rejected = std::move(rejected);
        rejected.clear();
        r.rounds.push_back(std::move(lr));
        r.model = std::move(best->first);
        kept = true;
      }
    }
    // When no term of the language passes while the residual stays predictable: a learned law
    // of the channel that predicts most of it, if that is a current or a voltage (a residual
    // that follows position or motion first is leakage, not a law), under the same checks.
    const ExplainableShare& ex = dx.explainable;
    if (!kept && !ex.within_noise && !ex.channels.empty() &&
        ex.channels.front().second > ex.noise_floor &&
        learned_channels.insert(ex.channels.front().first).second) {
      const std::string& channel = ex.channels.front().first;
      const double share = ex.channels.front().second;
      const Candidate* shape = nullptr;  // the best ranked one-channel term of the channel
      for (const Candidate& c : dx.candidates) {
        const auto e = c.channel == channel ? parse_expr_term(c.term) : nullptr;
        if (e && e->signal().sources.size() == 1) {
          shape = &c;
          break;
        }
      }
      const std::vector<std::string> law = learned_law(channel, shape, r.model, data);
      if (!law.empty()) {
        Model next = r.model;
        for (const auto& t : law) {
          if (next.add_term(t)) next.black_box_terms.push_back(t);
        }
        std::string added;
        for (const auto& t : law) added += (added.empty() ? "" : " + ") + t;
        kept = try_model(std::move(next), added, share, true);
      }
    }
    // The backward pass: an earlier round's term that the model no longer needs leaves (the
    // least needed first, one at a time), so long as the round still lowers the error of the
    // round before it.
    if (options.joint_steps && kept && r.rounds.size() >= 2) {
      const LoopRound before = r.rounds[r.rounds.size() - 2];
      std::set<std::string> added_now;  // this round's terms (" + " joins a pair or a law)
      for (size_t from = 0;;) {
        const std::string& a = r.rounds.back().added;
        const size_t to = a.find(" + ", from);
        added_now.insert(a.substr(from, to == std::string::npos ? std::string::npos : to - from));
        if (to == std::string::npos) break;
        from = to + 3;
      }
      for (;;) {
        const LoopRound& now = r.rounds.back();
        std::optional<std::pair<Model, LoopRound>> drop;
        std::string drop_term;
        double drop_share = INFINITY;
        for (const std::string& t : r.model.terms) {
          if (!removable(start, t) || added_now.count(t)) continue;
          auto [m, lr] = fit_score(without_term(r.model, t));
          const double share = -variance_share(now.heldout_std_nT, lr.heldout_std_nT);
          const bool validation_ok = !std::isfinite(now.validation_std_nT) ||
                                     -variance_share(now.validation_std_nT, lr.validation_std_nT) <
                                         0.25 * options.accept_fraction;
          if (share < 0.25 * options.accept_fraction && validation_ok &&
              lr.heldout_std_nT < before.heldout_std_nT && share < drop_share) {
            drop_share = share;
            drop_term = t;
            drop.emplace(std::move(m), std::move(lr));
          }
        }
        if (!drop) break;
        char why[200];
        std::snprintf(
            why, sizeof(why),
            "made redundant by later terms: without it the held-out error %.4f -> %.4f nT",
            now.heldout_std_nT, drop->second.heldout_std_nT);
        LoopRound& last = r.rounds.back();
        last.removed.emplace_back(drop_term, why);
        last.heldout_std_nT = drop->second.heldout_std_nT;
        last.all_std_nT = drop->second.all_std_nT;
        last.selection_std_nT = drop->second.selection_std_nT;
        last.confirmation_std_nT = drop->second.confirmation_std_nT;
        last.fom_nT = drop->second.fom_nT;
        last.validation_std_nT = drop->second.validation_std_nT;
        r.model = std::move(drop->first);
      }
    }
    if (!kept) {
      if (rejected.empty()) {
        r.stop_reason = dx.verdict;
      } else {
        r.stop_reason = eligible.empty() ? dx.verdict + "; " : "";
        r.stop_reason += "no term passes: ";
        for (size_t k = 0; k < rejected.size(); ++k) {
          r.stop_reason += (k ? "; " : "") + rejected[k].first + ": " + rejected[k].second;
        }
        r.stop_reason += ": stopped";
      }
      r.last = std::move(dx);
      break;
    }
  }
  return r;
}

}  // namespace magcomp
