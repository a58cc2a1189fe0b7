// magcomp: one round of diagnose_loop (loop_round.h).
#include "loop_round.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {

namespace {
// The share of `term`'s fit-row energy within the model's own span, as diagnosis `d` scored it
// (Candidate::base_span_share); NAN when `d` has no such candidate.
double span_share_in(const Diagnosis& d, const std::string& term) {
  for (const Candidate& c : d.candidates)
    if (c.term.text() == term) return c.base_span_share;
  return NAN;
}

}  // namespace

// The variants of one channel's term (lp(39.8), pow(2)|lp(39.9), ...) rank together and stand or
// fall together: a term whose size does not hold on the calibration rows fails there in each of
// its forms, and the next channel's term is the next try.
std::vector<size_t> single_tries(const std::vector<Eligible>& eligible) {
  std::vector<size_t> out;
  std::set<std::set<std::string>> seen;
  for (size_t k = 0; k < eligible.size() && out.size() < kTriesPerRound; ++k) {
    const std::set<std::string> f = fields_of(eligible[k].term);
    if (!f.empty() && !seen.insert(f).second) continue;
    out.push_back(k);
  }
  return out;
}

bool Round::try_model(Model next, const std::string& added, double explained, bool black_box) {
  next.coefficients.resize(0);
  fit_model(next, c_.flights);
  LoopRound lr = score(next, c_.flights, c_.truth, c_.held_out, c_.validation);
  const LoopRound& now = r_->rounds.back();
  std::string why = refusal(lr, now, c_.options);
  // A learned law has many columns: it must also explain the accepted share of the held-out
  // variance for each of its hinges, as every candidate must for its one term on each split
  // (five hinges fitted to what is left explain a few percent by their freedom alone).
  const double share_left = std::pow(lr.heldout_std_nT / now.heldout_std_nT, 2.0);
  const size_t hinges = next.terms.size() > r_->model.terms.size()
                            ? next.terms.size() - r_->model.terms.size()
                            : size_t{1};
  const double law_share = c_.options.accept_fraction * static_cast<double>(hinges);
  if (why.empty() && black_box && 1.0 - share_left < law_share) {
    char buf[200];
    std::snprintf(buf, sizeof(buf),
                  "the held-out error would fall by less than %.0f%% of its variance, %.0f%% for "
                  "each of its %zu hinges (%.3f -> %.3f nT)",
                  100 * law_share, 100 * c_.options.accept_fraction, hinges, now.heldout_std_nT,
                  lr.heldout_std_nT);
    why = buf;
  }
  // And, as every term must, lower the held-out error by the resolution: a smaller gain is what
  // the loop calls noise, whatever share of a small residual it is.
  if (why.empty() && black_box &&
      now.heldout_std_nT - lr.heldout_std_nT < c_.options.resolution_nT) {
    char buf[200];
    std::snprintf(buf, sizeof(buf),
                  "the held-out error would fall by less than the %.3f nT resolution (%.4f -> "
                  "%.4f nT)",
                  c_.options.resolution_nT, now.heldout_std_nT, lr.heldout_std_nT);
    why = buf;
  }
  if (!why.empty()) {
    rejected_.emplace_back(added, why);
    return false;
  }
  lr.round = round_;
  lr.added = added;
  lr.explained = explained;
  lr.black_box = black_box;
  keep(std::move(next), std::move(lr));
  return true;
}

void Round::keep(Model next, LoopRound lr) {
  lr.rejected = std::move(rejected_);
  rejected_.clear();
  r_->rounds.push_back(std::move(lr));
  r_->model = std::move(next);
}

std::pair<Model, LoopRound> Round::fit_score(Model m) const {
  m.coefficients.resize(0);
  fit_model(m, c_.flights);
  LoopRound lr = score(m, c_.flights, c_.truth, c_.held_out, c_.validation);
  return std::make_pair(std::move(m), std::move(lr));
}

bool Round::passes(double with_nT, double without_nT) const {
  return variance_share(with_nT, without_nT) >= c_.options.accept_fraction &&
         without_nT - with_nT >= c_.options.resolution_nT;
}

bool Round::improves_on(const LoopRound& lr, const LoopRound& now) const {
  return improves_in_place(lr, now) &&
         now.heldout_std_nT - lr.heldout_std_nT >= c_.options.resolution_nT;
}

bool halves_hold(const LoopRound& lr, const LoopRound& now) {
  return !(lr.selection_std_nT > now.selection_std_nT) &&
         !(lr.confirmation_std_nT > now.confirmation_std_nT);
}

bool Round::improves_in_place(const LoopRound& lr, const LoopRound& now) const {
  return refusal(lr, now, c_.options).empty() && halves_hold(lr, now) &&
         variance_share(lr.heldout_std_nT, now.heldout_std_nT) >= c_.options.accept_fraction;
}

bool Round::factor_resolved(const LoopRound& with, const LoopRound& without) const {
  if (passes(with.heldout_std_nT, without.heldout_std_nT)) return true;
  return variance_share(with.heldout_std_nT, without.heldout_std_nT) >= kFactorShare &&
         variance_share(with.selection_std_nT, without.selection_std_nT) >=
             c_.options.accept_fraction &&
         variance_share(with.confirmation_std_nT, without.confirmation_std_nT) >=
             c_.options.accept_fraction;
}

bool Round::holds_where_sized(const LoopRound& lr, const LoopRound& now) const {
  return !(lr.calibration_std_nT * lr.calibration_std_nT * (1.0 - c_.options.accept_fraction) >
           now.calibration_std_nT * now.calibration_std_nT);
}

bool Round::pair_passes(const LoopRound& lr, const LoopRound& alone_a,
                        const LoopRound& alone_b) const {
  const LoopRound& now = r_->rounds.back();
  const double accept = c_.options.accept_fraction;
  return refusal(lr, now, c_.options).empty() &&
         passes(lr.selection_std_nT, now.selection_std_nT) &&
         passes(lr.confirmation_std_nT, now.confirmation_std_nT) &&
         variance_share(lr.heldout_std_nT, alone_a.heldout_std_nT) >= accept &&
         variance_share(lr.heldout_std_nT, alone_b.heldout_std_nT) >= accept;
}

void Round::keep_together(std::pair<Model, LoopRound> fitted, const std::vector<std::string>& terms,
                          const std::vector<double>& alone_nT) {
  LoopRound lr = std::move(fitted.second);
  lr.round = round_;
  lr.added.clear();
  for (const std::string& t : terms) lr.added += (lr.added.empty() ? "" : " + ") + t;
  lr.explained = variance_share(lr.heldout_std_nT, r_->rounds.back().heldout_std_nT);
  lr.together = true;
  lr.alone_std_nT = alone_nT;
  keep(std::move(fitted.first), std::move(lr));
}

double Round::first_single_nT(const std::vector<Eligible>& eligible) const {
  for (size_t k : single_tries(eligible)) {
    Model next = r_->model;
    add_candidate_term(eligible[k].term, eligible[k].slow, c_.truth, &next);
    const LoopRound lr = fit_score(std::move(next)).second;
    if (refusal(lr, r_->rounds.back(), c_.options).empty()) return lr.heldout_std_nT;
  }
  return INFINITY;
}

bool Round::joint_set(const std::vector<Diagnosis>& dxs, const std::vector<Eligible>& eligible) {
  const LoopRound& now = r_->rounds.back();
  const double accept = c_.options.accept_fraction;
  std::optional<std::pair<Model, LoopRound>> best;
  std::vector<std::string> best_terms;
  std::vector<double> best_alone;
  for (const Diagnosis& d : dxs) {
    const std::vector<TermSpec>& terms = d.joint.terms;
    if (terms.size() < 2) continue;
    if (c_.options.refuse_within_span_terms &&
        std::any_of(terms.begin(), terms.end(), [&](const TermSpec& t) {
          return within_model_span(span_share_in(d, t.text()));
        }))
      continue;
    try {
      const auto with = [&](size_t skip, size_t only) {
        Model m = r_->model;
        for (size_t k = 0; k < terms.size(); ++k)
          if (k != skip && (only >= terms.size() || k == only))
            add_candidate_term(terms[k], false, c_.truth, &m);
        return fit_score(std::move(m));
      };
      const size_t none = terms.size();
      auto all = with(none, none);
      const LoopRound& lr = all.second;
      if (!refusal(lr, now, c_.options).empty() ||
          !passes(lr.selection_std_nT, now.selection_std_nT) ||
          !passes(lr.confirmation_std_nT, now.confirmation_std_nT))
        continue;
      if (best && !(lr.heldout_std_nT < best->second.heldout_std_nT)) continue;
      // Each term needed: without it, each half's error rises by the accepted share of the
      // variance and the resolution.
      bool needed = true;
      std::vector<double> without(terms.size());
      for (size_t k = 0; needed && k < terms.size(); ++k) {
        const LoopRound rest = with(k, none).second;
        without[k] = rest.heldout_std_nT;
        needed = passes(lr.selection_std_nT, rest.selection_std_nT) &&
                 passes(lr.confirmation_std_nT, rest.confirmation_std_nT);
      }
      if (!needed) continue;
      std::vector<double> alone(terms.size());  // of a pair: the pair without the other
      for (size_t k = 0; k < terms.size(); ++k)
        alone[k] = terms.size() == 2 ? without[1 - k] : with(none, k).second.heldout_std_nT;
      best.emplace(std::move(all));
      best_terms.clear();
      for (const TermSpec& t : terms) best_terms.push_back(t.text());
      best_alone = std::move(alone);
    } catch (const Error&) {
    }
  }
  if (!best) return false;
  const double single_nT = first_single_nT(eligible);
  if (variance_share(best->second.heldout_std_nT, single_nT) < accept ||
      single_nT - best->second.heldout_std_nT < c_.options.resolution_nT)
    return false;
  keep_together(std::move(*best), best_terms, best_alone);
  return true;
}

bool Round::lag_with_partner(const std::vector<Diagnosis>& dxs,
                             const std::vector<Eligible>& eligible) {
  std::optional<std::pair<Model, LoopRound>> partnered;
  std::string partnered_a, partnered_b;
  double partnered_alone[2] = {NAN, NAN};
  for (const Diagnosis& d : dxs) {
    if (d.candidates.empty()) continue;
    const Candidate& top = d.candidates.front();
    if (top.partner.empty() || (top.accepted && top.explained_fraction >= c_.min_share)) continue;
    try {
      Model with_a = r_->model, with_b = r_->model, with_both = r_->model;
      add_candidate_term(top.term, top.slow, c_.truth, &with_a);
      add_candidate_term(top.partner, false, c_.truth, &with_b);
      add_candidate_term(top.term, top.slow, c_.truth, &with_both);
      add_candidate_term(top.partner, false, c_.truth, &with_both);
      const LoopRound alone_a = fit_score(std::move(with_a)).second;
      const LoopRound alone_b = fit_score(std::move(with_b)).second;
      auto both = fit_score(std::move(with_both));
      if (!pair_passes(both.second, alone_a, alone_b)) continue;
      if (partnered && !(both.second.heldout_std_nT < partnered->second.heldout_std_nT)) continue;
      partnered.emplace(std::move(both));
      partnered_a = top.term.text();
      partnered_b = top.partner.text();
      partnered_alone[0] = alone_a.heldout_std_nT;
      partnered_alone[1] = alone_b.heldout_std_nT;
    } catch (const Error&) {
    }
  }
  if (!partnered) return false;
  if (!(partnered->second.heldout_std_nT < first_single_nT(eligible))) return false;
  keep_together(std::move(*partnered), {partnered_a, partnered_b},
                {partnered_alone[0], partnered_alone[1]});
  return true;
}

bool Round::first_single(const std::vector<Eligible>& eligible) {
  for (size_t k : single_tries(eligible)) {
    const Model before = r_->model;
    Model next = before;
    add_candidate_term(eligible[k].term, eligible[k].slow, c_.truth, &next);
    if (try_model(std::move(next), eligible[k].term, eligible[k].explained, false)) {
      const size_t kept = look_alikes(before, eligible, fewer_columns(before, eligible, k));
      LoopRound& now = r_->rounds.back();
      const double prev_nT =
          r_->rounds.size() < 2 ? NAN : r_->rounds[r_->rounds.size() - 2].heldout_std_nT;
      const double explained2 = prev_nT * prev_nT - now.heldout_std_nT * now.heldout_std_nT;
      if (explained2 > 0)
        now.steady_factors = steady_factors(c_.flights, fields_of(eligible[kept].term), c_.truth,
                                            std::sqrt(explained2), c_.options.resolution_nT);
      now.paired_factors = paired_factors(eligible, kept);
      return true;
    }
  }
  return false;
}

std::vector<std::string> paired_factors(const std::vector<Eligible>& eligible, size_t kept) {
  std::vector<std::string> out;
  const std::set<std::string> kept_fields = fields_of(eligible[kept].term);
  if (kept_fields.size() != 1) return out;
  for (size_t j = 0; j < eligible.size(); ++j) {
    const ExprTerm* e = eligible[j].term.expr();
    if (j == kept || !e || e->signal().sources.size() != 2 ||
        !(eligible[j].explained >= eligible[kept].explained))
      continue;
    const std::set<std::string> fields = fields_of(eligible[j].term);
    if (fields.size() != 2 || !fields.count(*kept_fields.begin())) continue;
    for (const std::string& y : fields)
      if (!kept_fields.count(y) && is_aircraft_state(y) &&
          std::find(out.begin(), out.end(), y) == out.end())
        out.push_back(y);
  }
  return out;
}

size_t Round::fewer_columns(const Model& before, const std::vector<Eligible>& eligible,
                            size_t kept) {
  const std::set<std::string> kept_fields = fields_of(eligible[kept].term);
  if (kept_fields.empty() || r_->rounds.size() < 2) return kept;
  const LoopRound previous = r_->rounds[r_->rounds.size() - 2];
  const Eigen::Index kept_columns = eligible[kept].term.term().columns();
  std::optional<std::pair<Model, LoopRound>> best;
  size_t best_j = kept;
  for (size_t j = 0; j < eligible.size(); ++j) {
    if (j == kept || eligible[j].term.term().columns() >= kept_columns ||
        fields_of(eligible[j].term) != kept_fields)
      continue;
    try {
      Model m = before;
      add_candidate_term(eligible[j].term, eligible[j].slow, c_.truth, &m);
      auto fitted = fit_score(std::move(m));
      const LoopRound& lr = fitted.second;
      if (!refusal(lr, previous, c_.options).empty()) continue;
      if (passes(r_->rounds.back().heldout_std_nT, lr.heldout_std_nT)) continue;  // beaten
      if (best && !(lr.heldout_std_nT < best->second.heldout_std_nT)) continue;
      best.emplace(std::move(fitted));
      best_j = j;
    } catch (const Error&) {
    }
  }
  if (!best) return kept;
  char why[200];
  std::snprintf(why, sizeof(why),
                "as few columns do as well: %s leaves %.4f nT held out, %.4f with %lld columns",
                eligible[best_j].term.text().c_str(), best->second.heldout_std_nT,
                r_->rounds.back().heldout_std_nT, static_cast<long long>(kept_columns));
  in_place_of_kept(std::move(*best), eligible[best_j], why);
  return best_j;
}

void Round::in_place_of_kept(std::pair<Model, LoopRound> fitted, const Eligible& term,
                             const std::string& why) {
  LoopRound& now = r_->rounds.back();
  LoopRound lr = std::move(fitted.second);
  lr.round = now.round;
  lr.added = term.term.text();
  lr.explained = term.explained;
  lr.black_box = false;
  lr.rejected = std::move(now.rejected);
  lr.rejected.emplace_back(now.added, why);
  now = std::move(lr);
  r_->model = std::move(fitted.first);
}

size_t Round::look_alikes(const Model& before, const std::vector<Eligible>& eligible, size_t kept) {
  const std::set<std::string> kept_fields = fields_of(eligible[kept].term);
  if (kept_fields.empty() || r_->rounds.size() < 2) return kept;  // a lag names no channel
  LoopRound& now = r_->rounds.back();
  const LoopRound previous = r_->rounds[r_->rounds.size() - 2];
  std::set<std::string> named = kept_fields;          // one look-alike per channel set
  std::optional<std::pair<Model, LoopRound>> better;  // a look-alike that does better
  size_t better_j = kept;
  for (size_t j = 0, tried = 0; j < eligible.size() && tried < kLookAlikeTries; ++j) {
    if (j == kept) continue;
    const std::set<std::string> fields = fields_of(eligible[j].term);
    if (fields.empty()) continue;
    bool shares_a_channel = false;
    for (const std::string& x : fields) shares_a_channel = shares_a_channel || named.count(x) > 0;
    if (shares_a_channel) continue;
    ++tried;
    try {
      Model m = before;
      add_candidate_term(eligible[j].term, eligible[j].slow, c_.truth, &m);
      auto fitted = fit_score(std::move(m));
      const LoopRound& lr = fitted.second;
      if (!refusal(lr, previous, c_.options).empty()) continue;
      // Not told apart: the kept term is not better by the accepted share and the resolution.
      if (passes(now.heldout_std_nT, lr.heldout_std_nT)) continue;
      now.look_alikes.emplace_back(eligible[j].term.text(), lr.heldout_std_nT);
      if (auto ratio = look_alike_ratio(c_.flights, kept_fields, fields, c_.truth)) {
        ratio->term = eligible[j].term.text();
        now.look_alike_ratios.push_back(std::move(*ratio));
      }
      named.insert(fields.begin(), fields.end());
      if (c_.options.better_look_alike && refusal(lr, now, c_.options).empty() &&
          holds_where_sized(lr, now) && passes(lr.heldout_std_nT, now.heldout_std_nT) &&
          (!better || lr.heldout_std_nT < better->second.heldout_std_nT)) {
        better = std::move(fitted);
        better_j = j;
      }
    } catch (const Error&) {
    }
  }
  if (!better) return kept;
  // A look-alike that beats the kept term by what a term must gain takes its place, and its own
  // look-alikes are listed (each such exchange lowers the held-out error by the accepted share,
  // so it ends).
  char why[300];
  std::snprintf(why, sizeof(why),
                "a look-alike of another channel does better: %s leaves %.4f nT held out, this "
                "term %.4f",
                eligible[better_j].term.text().c_str(), better->second.heldout_std_nT,
                now.heldout_std_nT);
  in_place_of_kept(std::move(*better), eligible[better_j], why);
  return look_alikes(before, eligible, better_j);
}

bool Round::pair_acting_together(const std::vector<Diagnosis>& dxs) {
  // The pool: for each of the three channels that predict most of the residual (and that the
  // search gives terms of), its plain term and its first ranked term, whatever their share
  // alone: effects that cancel one another show in the residual's channels, not in each term's
  // share.
  constexpr size_t kResidualChannels = 3;
  std::vector<Candidate> pool;
  std::set<std::string> in_pool;
  const auto take = [&](const Diagnosis& d, const Candidate& c) {
    if (c_.options.refuse_within_span_terms && within_model_span(span_share_in(d, c.term.text())))
      return;
    if (in_pool.insert(c.term.text()).second) pool.push_back(c);
  };
  for (const Diagnosis& d : dxs) {
    const ExplainableShare& ex0 = d.explainable;
    if (ex0.within_noise) continue;
    for (size_t k = 0; k < ex0.channels.size() && k < kResidualChannels; ++k) {
      const std::string& channel = ex0.channels[k].first;
      const auto first = std::find_if(d.candidates.begin(), d.candidates.end(),
                                      [&](const Candidate& c) { return c.channel == channel; });
      if (first == d.candidates.end()) continue;
      Candidate plain;
      plain.term = TermSpec((is_electrical(channel) ? "current:" : "field:") + channel);
      plain.channel = channel;
      take(d, plain);
      take(d, *first);
    }
  }
  std::vector<LoopRound> alone(pool.size());
  for (size_t a = 0; a < pool.size(); ++a) {
    alone[a].heldout_std_nT = NAN;  // a term that cannot be fitted here is left out
    try {
      Model next = r_->model;
      add_candidate_term(pool[a].term, pool[a].slow, c_.truth, &next);
      alone[a] = fit_score(std::move(next)).second;
    } catch (const Error&) {
    }
  }
  const LoopRound& now = r_->rounds.back();
  double best_std = INFINITY;
  std::optional<std::pair<Model, LoopRound>> best;
  size_t best_a = 0, best_b = 0;
  for (size_t a = 0; a < pool.size(); ++a) {
    for (size_t b = a + 1; b < pool.size(); ++b) {
      if (pool[a].channel == pool[b].channel || !std::isfinite(alone[a].heldout_std_nT) ||
          !std::isfinite(alone[b].heldout_std_nT))
        continue;
      if (refusal(alone[a], now, c_.options).empty() && refusal(alone[b], now, c_.options).empty())
        continue;  // both lower the error alone: not a pair that only acts together
      Model next = r_->model;
      add_candidate_term(pool[a].term, pool[a].slow, c_.truth, &next);
      add_candidate_term(pool[b].term, pool[b].slow, c_.truth, &next);
      auto [fitted, lr] = fit_score(std::move(next));
      if (!pair_passes(lr, alone[a], alone[b])) continue;
      if (lr.heldout_std_nT < best_std) {
        best_std = lr.heldout_std_nT;
        best.emplace(std::move(fitted), std::move(lr));
        best_a = a;
        best_b = b;
      }
    }
  }
  if (!best) return false;
  keep_together(std::move(*best), {pool[best_a].term.text(), pool[best_b].term.text()},
                {alone[best_a].heldout_std_nT, alone[best_b].heldout_std_nT});
  return true;
}

bool Round::learned_law_of_channel(const std::vector<Diagnosis>& dxs,
                                   std::set<std::string>* learned_channels) {
  // The flight whose residual is predictable (the first such), and its data. The channel must be
  // a state of the aircraft (learned_law): a residual that follows position or motion first is
  // leakage, not a law.
  size_t law_flight = 0;
  while (law_flight + 1 < dxs.size() && dxs[law_flight].explainable.within_noise) ++law_flight;
  const Diagnosis& law_dx = dxs[law_flight];
  const ExplainableShare& ex = law_dx.explainable;
  if (ex.within_noise || ex.channels.empty() || !(ex.channels.front().second > ex.noise_floor) ||
      !learned_channels->insert(ex.channels.front().first).second)
    return false;
  const std::string& channel = ex.channels.front().first;
  const double share = ex.channels.front().second;
  const Candidate* shape = nullptr;  // the best ranked one-channel term of the channel
  for (const Candidate& c : law_dx.candidates) {
    const ExprTerm* e = c.channel == channel ? c.term.expr() : nullptr;
    if (e && e->signal().sources.size() == 1) {
      shape = &c;
      break;
    }
  }
  const std::vector<TermSpec> law = learned_law(channel, shape, r_->model, *c_.flights[law_flight]);
  if (law.empty()) return false;
  Model next = r_->model;
  for (const auto& t : law) {
    if (next.add_term(t)) next.black_box_terms.push_back(t);
  }
  std::string added;
  for (const auto& t : law) added += (added.empty() ? "" : " + ") + t.text();
  return try_model(std::move(next), added, share, true);
}

}  // namespace magcomp::loop_steps
