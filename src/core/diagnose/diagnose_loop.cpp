// magcomp: the diagnose -> add -> refit loop.
#include "magcomp/core/diagnose/diagnose_loop.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>

#include "loop_round.h"
#include "loop_steps.h"
#include "magcomp/core/diagnose/diagnose_season.h"
#include "magcomp/core/error.h"
#include "magcomp/core/fit/model_fit.h"

namespace magcomp {
using loop_steps::better_lambda;
using loop_steps::Eligible;
using loop_steps::eligible_candidates;
using loop_steps::HeldOut;
using loop_steps::lines_beside_calibration;
using loop_steps::refusal;
using loop_steps::score;
using loop_steps::variance_share;

LoopResult diagnose_loop(const Model& start, const FlightData& data, const std::string& truth,
                         int max_rounds, double min_share, const DiagnoseOptions& options,
                         const std::function<void(int, const Diagnosis&)>& on_round,
                         const FlightData* validation) {
  std::function<void(int, size_t, const Diagnosis&)> each;
  if (on_round) each = [&](int round, size_t, const Diagnosis& dx) { on_round(round, dx); };
  return diagnose_loop(start, std::vector<const FlightData*>{&data}, truth, max_rounds, min_share,
                       options, each, validation);
}

LoopResult diagnose_loop(const Model& start, const std::vector<const FlightData*>& flights,
                         const std::string& truth, int max_rounds, double min_share,
                         const DiagnoseOptions& options,
                         const std::function<void(int, size_t, const Diagnosis&)>& on_round,
                         const FlightData* validation) {
  if (flights.empty()) throw Error("diagnose: no flight given");
  std::set<std::string> learned_channels;  // one learned law per channel
  std::set<std::string> named_channels;    // one plain term tried per channel
  std::set<std::string> taken_out;         // terms an exchange took out (never put back by one)
  std::set<std::string> dropped_refined;   // terms Round::redundant_once_refined dropped
  int exchanges = 0;
  bool lag_corrected = false;           // the lag estimated again once the rounds are spent
  bool norm_tried_at_end = false;       // TL as the exact norm tried once the rounds are spent
  bool norm_with_a_term_tried = false;  // Round::exact_norm_with_a_term tried (once per loop)
  bool flights_are_halves = false;      // the flights are the held-out halves (across_flights)
  LoopResult r;
  r.model = start;
  if (!r.model.fitted()) fit_model(r.model, flights);
  // Slow terms are sized on the calibration rows first; on the held-out lines too (cross-fitted)
  // only when a round keeps nothing that way: a drift the calibration barely shows is sized
  // where its channel moves, while a channel that only trends with the error over the lines
  // (a stand-in) never displaces a term the calibration rows size.
  DiagnoseOptions round_options = options;
  round_options.slow_terms_on_lines = false;
  const bool lines_fallback = options.slow_terms_on_lines && r.model.fit.slow_lines.empty();
  const std::vector<double> lines =
      lines_fallback ? lines_beside_calibration(r.model.fit, flights) : std::vector<double>{};
  std::vector<HeldOut> held_out(flights.size());  // each flight's held-out samples, in two halves
  const loop_steps::LoopContext context{start,      flights, truth,    held_out,
                                        validation, options, min_share};
  const bool backward_after_revisits = options.joint_steps && options.backward_after_revisits;
  // Over one flight without a validation flight, as the loop ends: each kept drift that a
  // channel shifted in time matches as well leaves (Round::drop_chance_slow_term), and what the
  // model took in with it or after it leaves where the held-out lines do better without it too
  // (Round::shed_after_chance_drift). The drifts taken out, joined by ", " ("" when none).
  const auto chance_drifts_dropped = [&] {
    std::string out;
    if (!options.chance_control || flights.size() != 1 || validation) return out;
    std::set<std::string> audited;
    for (;;) {
      loop_steps::Round audit(context, max_rounds, &r);
      const size_t removed_before = r.rounds.back().removed.size();
      if (!audit.drop_chance_slow_term(round_options, &audited)) break;
      const std::string drift = r.rounds.back().removed[removed_before].first;
      out += (out.empty() ? "" : ", ") + drift;
      // What was taken in with it or after it, sized with it in place, is judged again.
      audit.shed_after_chance_drift(drift);
    }
    return out;
  };
  for (int round = 1;; ++round) {
    const size_t rounds_before_end = r.rounds.size();
    // The rounds spent: the rounds limit what is added, not what is corrected. A kept term chosen
    // while other effects were still in the residual still gives way to what the model without
    // it ranks first (Round::exchange, within the loop's kExchanges; sharing the last round's
    // number).
    while (round > max_rounds && round > 1 && options.exchange_terms &&
           exchanges < loop_steps::kExchanges) {
      loop_steps::Round swap(context, max_rounds, &r);
      if (!swap.exchange(round_options, &taken_out)) break;
      ++exchanges;
    }
    // Each kept term's parameters are still estimated again with every other term in place (no
    // candidate added: Round::refine_parameters without diagnoses), once per kept term at most: a
    // term so written keeps its parameters after (a slow stand-in's time constant would otherwise
    // walk out by the retiming's range each time).
    for (std::set<std::string> refined; round > max_rounds && round > 1 &&
                                        options.refine_parameters &&
                                        refined.size() < r.model.terms.size();) {
      loop_steps::Round refit(context, max_rounds, &r);
      if (!refit.refine_parameters({}, refined)) break;
      for (const std::string& t : loop_steps::step_terms(r.rounds.back().added)) refined.insert(t);
    }
    // Then each kept product whose factor earns no place is still written without it, before
    // the last diagnosis.
    while (round > max_rounds && round > 1 && options.drop_idle_factors) {
      loop_steps::Round simplify(context, max_rounds, &r);
      if (!simplify.drop_idle_factors()) break;
    }
    // And each kept term whose field scales with a channel the flights hold nearly steady is
    // written as that product (at most one per kept term).
    for (size_t products = 0; round > max_rounds && round > 1 && options.steady_factor_products &&
                              products < r.model.terms.size();
         ++products) {
      loop_steps::Round scale(context, max_rounds, &r);
      if (!scale.steady_factor_in_place()) break;
    }
    // And each kept term that a look-alike beats with every other term in place gives way to it
    // (at most one swap per kept term).
    for (size_t swaps = 0; round > max_rounds && round > 1 && options.better_look_alike &&
                           swaps < r.model.terms.size();
         ++swaps) {
      loop_steps::Round rename(context, max_rounds, &r);
      if (!rename.better_look_alike_in_place()) break;
    }
    // And a kept term another kept term makes redundant, its parameters estimated again, leaves
    // (at most one per kept term over the loop).
    while (round > max_rounds && round > 1 && options.redundant_once_refined) {
      loop_steps::Round drop(context, max_rounds, &r);
      if (!drop.redundant_once_refined(&dropped_refined)) break;
    }
    // Then a term the model so changed makes redundant leaves (Round::backward_pass).
    if (backward_after_revisits && r.rounds.size() > rounds_before_end) {
      loop_steps::Round last(context, max_rounds, &r);
      last.backward_pass();
    }
    std::vector<Diagnosis> dxs;
    const auto diagnose_all = [&] {
      dxs.clear();
      for (size_t f = 0; f < flights.size(); ++f)
        dxs.push_back(diagnose(r.model, *flights[f], truth, round_options));
    };
    diagnose_all();
    for (size_t f = 0; round == 1 && f < flights.size(); ++f) {
      held_out[f].fold = dxs[f].heldout_fold;
      held_out[f].line = flights[f]->has("line") ? Eigen::VectorXd(flights[f]->column("line"))
                                                 : Eigen::VectorXd::Zero(flights[f]->size());
    }
    if (round == 1) {
      r.rounds.push_back(score(r.model, flights, truth, held_out, validation));
      // Flights of one aircraft: the model fitted on all of them leaves on each about what it
      // leaves fitted on that flight alone (its diagnosis's baseline).
      for (size_t f = 0; flights.size() > 1 && f < flights.size(); ++f) {
        const double joint = r.rounds[0].flight_heldout_std_nT[f];
        const double alone = dxs[f].baseline_std_nT;
        if (joint > 3.0 * alone + options.resolution_nT) {
          char buf[400];
          std::snprintf(buf, sizeof(buf),
                        "%s: the model fitted on all the flights leaves %.3f nT on its held-out "
                        "lines, %.3f nT fitted on it alone: are these flights of one aircraft "
                        "with the same sensors?",
                        flights[f]->source().c_str(), joint, alone);
          r.warnings.push_back(buf);
        }
      }
    }
    // The ridge strength, chosen on the held-out lines before the round's terms; the round is
    // diagnosed again with it.
    // Without --choose-lambda, the same step when the round's first eligible term lies within
    // the model's own span (kWithinSpanShare): its gain would be the ridge's, named after a
    // channel that carries no effect.
    // The candidates the loop may add, in rank order: accepted, and explaining at least
    // min_share on both halves (a term ranked first on the selection lines may explain little
    // on the confirmation lines, where the error may lie). Over several flights: accepted so on
    // at least one of them (an effect one flight barely shows is another's to find), ranked as
    // the flights' diagnoses together rank it (merge_diagnoses).
    const bool span_too = !options.refuse_within_span_terms;
    std::vector<Eligible> eligible = eligible_candidates(dxs, min_share, true);
    std::optional<Eligible> span_term;
    if (options.ridge_for_span_terms && !eligible.empty() &&
        within_model_span(eligible.front().base_span_share))
      span_term = eligible.front();
    if (!span_too) eligible = eligible_candidates(dxs, min_share, false);
    // TL written as the exact norm, and fitted against the reference where the flights record
    // it, before the round's terms until it is kept, when it explains at least what the round's
    // first term would (or no term is eligible), and once more when the rounds are spent: an
    // effect that dominates the residual is written first, and what TL's expansion drops shows
    // once those are. The round is diagnosed again with it, and a term it makes redundant leaves.
    if (options.exact_norm && (round <= max_rounds || !norm_tried_at_end)) {
      if (round > max_rounds) norm_tried_at_end = true;
      auto step = loop_steps::exact_norm_step(r.model, r.rounds.back(), flights, truth, held_out,
                                              validation, options);
      if (step && round <= max_rounds && !eligible.empty() &&
          step->first.second.explained < eligible.front().explained)
        step.reset();  // the round's first term explains more: it goes first
      if (step) {
        LoopRound lr = std::move(step->first.second);
        lr.round = round;
        std::string added;
        for (const TermSpec& t : step->first.first.terms)
          if (std::find(r.model.terms.begin(), r.model.terms.end(), t) == r.model.terms.end())
            added += (added.empty() ? "" : " + ") + t.text();
        lr.added = added;
        lr.model_change =
            step->second.empty() ? "TL as the exact norm" : "TL as the exact norm; " + step->second;
        r.rounds.push_back(std::move(lr));
        r.model = std::move(step->first.first);
        if (backward_after_revisits) {
          loop_steps::Round last(context, max_rounds, &r);
          last.backward_pass();
        }
        diagnose_all();
        if (round > max_rounds) continue;  // the kept terms revisited with it in place
        eligible = eligible_candidates(dxs, min_share, true);
        span_term.reset();
        if (options.ridge_for_span_terms && !eligible.empty() &&
            within_model_span(eligible.front().base_span_share))
          span_term = eligible.front();
        if (!span_too) eligible = eligible_candidates(dxs, min_share, false);
      }
    }
    if ((options.choose_lambda || span_term) && round <= max_rounds) {
      if (auto step = better_lambda(r.model, start.fit.lambda, r.rounds.back(), flights, truth,
                                    held_out, validation, options)) {
        LoopRound lr = std::move(step->second);
        char added[64];
        std::snprintf(added, sizeof(added), "fit.lambda %.3g", step->first.fit.lambda);
        lr.round = round;
        lr.added = added;
        lr.explained = variance_share(lr.heldout_std_nT, r.rounds.back().heldout_std_nT);
        lr.regularisation = true;
        if (span_term) {
          lr.in_place_of = span_term->term.text();
          lr.in_place_of_span_share = span_term->base_span_share;
        }
        r.rounds.push_back(std::move(lr));
        r.model = std::move(step->first);
        diagnose_all();
        eligible = eligible_candidates(dxs, min_share, span_too);
      }
    }
    for (size_t f = 0; on_round && f < flights.size(); ++f) on_round(round, f, dxs[f]);
    // Over several flights, what is said of them together.
    const std::string verdict =
        flights.size() == 1 ? dxs.front().verdict : merge_diagnoses(dxs).verdict;
    const auto finish = [&](std::string reason) {
      r.stop_reason = std::move(reason);
      r.last = dxs.front();
      r.last_flights = std::move(dxs);
      // The round's diagnoses size slow candidates on the calibration rows (or cross-fitted on
      // the lines): a heater whose channel moves on one survey line only never ranks there. The
      // model as it ends, diagnosed as `diagnose` would, names such a term (one_half_term.h):
      // what a second flight would confirm.
      if (flights.size() == 1 && options.slow_terms_on_lines && r.last.one_half.term.empty() &&
          r.stop_reason.rfind("structure remains", 0) == 0) {
        const Diagnosis as_given = diagnose(r.model, *flights.front(), truth, options);
        if (!as_given.one_half.term.empty()) {
          r.last.one_half = as_given.one_half;
          r.stop_reason += one_half_clause(as_given.one_half);
        }
      }
    };
    // The rounds spent, the model's own lag is still estimated again with every other term in
    // place when the diagnosis ranks its new value as a candidate that passes (once): a lag
    // found before the other effects were written is a correction, not an added term.
    if (round > max_rounds && options.refine_parameters && !lag_corrected &&
        r.model.scalar_lag_s() != 0.0) {
      lag_corrected = true;
      std::vector<Eligible> lag;
      for (const Eligible& e : eligible)
        if (e.term.text().rfind("lag:", 0) == 0) lag.push_back(e);
      std::string old_lag;
      for (const TermSpec& t : r.model.terms)
        if (t.text().rfind("lag:", 0) == 0) old_lag = t.text();
      loop_steps::Round fix(context, max_rounds, &r);
      const double before_nT = r.rounds.back().heldout_std_nT;
      if (!lag.empty() && fix.first_single(lag)) {
        LoopRound& now = r.rounds.back();
        char why[200];
        std::snprintf(why, sizeof(why),
                      "its value estimated again with every other term in place: held-out error "
                      "%.4f -> %.4f nT",
                      before_nT, now.heldout_std_nT);
        if (!old_lag.empty()) now.replaced.emplace_back(old_lag, why);
        if (backward_after_revisits) fix.backward_pass();
        continue;
      }
    }
    // The model as it ends without the drifts taken out, diagnosed again (its diagnosis ranks
    // them first once more: the flight cannot say more of them), and what the loop says.
    const auto without_chance_drifts = [&](const std::string& dropped) {
      diagnose_all();
      return "structure remains: " + dropped +
             " taken out: a drift this flight cannot tell from chance (its round's removed says "
             "by how much); a second flight (--data A.h5,B.h5 or --validate NEXT.h5) tells "
             "whether its channel carries it";
    };
    if (round > max_rounds) {
      const std::string dropped = chance_drifts_dropped();
      finish(dropped.empty() ? "stopped after " + std::to_string(max_rounds) + " rounds; " + verdict
                             : "stopped after " + std::to_string(max_rounds) + " rounds; " +
                                   without_chance_drifts(dropped));
      break;
    }
    // The round's ways to change the model, in order (loop_round.h); the first kept ends the
    // round, then the backward pass.
    const auto attempt = [&](loop_steps::Round& step, const std::vector<Eligible>& el) {
      bool kept = options.joint_steps && step.lag_with_partner(dxs, el);
      kept = kept || (options.joint_steps && step.joint_set(dxs, el));
      kept = kept || step.first_single(step.looking_ahead(el, round_options));
      // Pairs only while some flight's residual stays predictable (the learned law checks its
      // own flight).
      const bool predictable = std::any_of(
          dxs.begin(), dxs.end(), [](const Diagnosis& d) { return !d.explainable.within_noise; });
      kept = kept || (options.joint_steps && predictable && step.pair_acting_together(dxs));
      kept = kept || step.named_channel_term(dxs, &named_channels);
      kept = kept || step.learned_law_of_channel(dxs, &learned_channels);
      kept = kept || (options.joint_steps && step.size_following_a_state());
      if (options.joint_steps && kept) step.backward_pass();
      return kept;
    };
    loop_steps::Round step(context, round, &r);
    // The terms within the model's own span ranked before the first the round may add: never
    // added, each said so among the round's refusals.
    for (const Eligible& e : eligible_candidates(dxs, min_share, true)) {
      if (span_too || !within_model_span(e.base_span_share)) break;
      char why[300];
      std::snprintf(why, sizeof(why),
                    "%.4f%% of its columns' energy on the fit rows lies within the model's own "
                    "columns: its size there is the ridge's split of its channel's level, which "
                    "another flight would read through it",
                    100 * e.base_span_share);
      step.refuse(e.term.text(), why);
    }
    // The same round with the slow terms sized on the held-out lines too (lines_fallback): the
    // model it starts from keeps its round's scores; a step is judged against them as any other.
    // With `first`, only when a slow candidate there dominates (DiagnoseOptions::
    // slow_lines_first); else after the calibration rows keep nothing. Kept, the lines size the
    // slow terms from then on.
    std::optional<std::vector<Diagnosis>> dxs_on_lines;  // diagnosed once per round: the
    std::vector<TermSpec> terms_on_lines;                // model with these terms
    bool on_lines_refused = false;
    const auto on_lines_round =
        [&](bool first, const std::vector<std::pair<std::string, std::string>>& refused_before) {
          const Model before = r.model;
          const std::vector<Diagnosis> dxs_before = dxs;
          const std::set<std::string> learned_before = learned_channels;
          const std::set<std::string> named_before = named_channels;
          round_options.slow_terms_on_lines = true;
          r.model.fit.slow_lines = lines;
          if (dxs_on_lines && terms_on_lines == r.model.terms) {
            dxs = *dxs_on_lines;
          } else {
            diagnose_all();
            dxs_on_lines = dxs;
            terms_on_lines = r.model.terms;
          }
          const auto restore = [&] {
            round_options.slow_terms_on_lines = false;
            r.model = before;
            dxs = dxs_before;
            learned_channels = learned_before;
            named_channels = named_before;
            return false;
          };
          if (first) {
            double slow_share = 0.0;
            for (const Eligible& e : eligible_candidates(dxs, min_share, span_too))
              if (e.slow) slow_share = std::max(slow_share, e.explained);
            const double rows_share = eligible.empty() ? 0.0 : eligible.front().explained;
            if (slow_share < kSlowLinesFirstShare || slow_share < kSlowLinesFirstRatio * rows_share)
              return restore();
          }
          loop_steps::Round on_lines(context, round, &r);
          // The candidates of the diagnosis with slow terms sized on the lines, then the slow ones
          // the calibration-sized round could not keep: the screen sizes a slow candidate on the
          // lines, which the fit now does too (a heater the calibration rows barely show, sized
          // there, can raise the held-out error its screen said it lowers). Not a channel a kept
          // slow term reads: a second time constant of it is the kept term's shape, which
          // Round::retimed_slow_term estimates.
          std::set<std::string> slow_channels;
          for (const std::string& t : r.model.slow_terms)
            for (const std::string& c : loop_steps::fields_of(TermSpec(t))) slow_channels.insert(c);
          std::vector<Eligible> on_lines_eligible = eligible_candidates(dxs, min_share, span_too);
          for (const Eligible& e : eligible) {
            const bool listed = std::any_of(on_lines_eligible.begin(), on_lines_eligible.end(),
                                            [&](const Eligible& o) { return o.term == e.term; });
            const std::set<std::string> channels = loop_steps::fields_of(e.term);
            const bool slow_channel =
                std::any_of(channels.begin(), channels.end(),
                            [&](const std::string& c) { return slow_channels.count(c) > 0; });
            if (e.slow && !listed && !slow_channel) on_lines_eligible.push_back(e);
          }
          if (!attempt(on_lines, on_lines_eligible)) {
            on_lines_refused = true;  // the same attempt would refuse it again
            return restore();
          }
          LoopRound& kept_round = r.rounds.back();
          kept_round.slow_on_lines = true;
          kept_round.rejected.insert(kept_round.rejected.begin(), refused_before.begin(),
                                     refused_before.end());
          return true;
        };
    const bool lines_open = lines_fallback && !round_options.slow_terms_on_lines && !lines.empty();
    // Slow candidates on the lines first: only where no candidate the calibration rows size
    // explains enough that a slow one could dominate it.
    bool kept = lines_open && options.slow_lines_first &&
                (eligible.empty() || eligible.front().explained < kSlowLinesFirstShare) &&
                on_lines_round(true, step.rejected());
    if (!kept) kept = attempt(step, eligible);
    if (!kept && lines_open && !round_options.slow_terms_on_lines && !on_lines_refused)
      kept = on_lines_round(false, step.rejected());
    // Nothing passes and TL as the exact norm was refused alone: the exact norm together with
    // what its diagnosis ranks first (Round::exact_norm_with_a_term), once per loop.
    if (!kept && options.exact_norm && options.norm_with_a_term && options.joint_steps &&
        !norm_with_a_term_tried && round <= max_rounds &&
        std::find(r.model.terms.begin(), r.model.terms.end(), "norm") == r.model.terms.end()) {
      norm_with_a_term_tried = true;
      loop_steps::Round together(context, round, &r);
      if (together.exact_norm_with_a_term(round_options)) {
        if (backward_after_revisits) together.backward_pass();
        auto& refused = r.rounds.back().rejected;
        refused.insert(refused.begin(), step.rejected().begin(), step.rejected().end());
        continue;
      }
    }
    // Nothing passes over several flights: a term a flight names but its own halves cannot
    // confirm (its channel moves on one half's lines alone) is judged with the flights as the
    // halves (loop_steps::across_flights); kept, they stay the halves.
    if (!kept && options.across_flights && flights.size() > 1 && !flights_are_halves &&
        round <= max_rounds && loop_steps::across_flights(context, round, lines, &r, &held_out)) {
      flights_are_halves = true;
      if (!r.model.fit.slow_lines.empty()) round_options.slow_terms_on_lines = true;
      auto& refused = r.rounds.back().rejected;
      refused.insert(refused.begin(), step.rejected().begin(), step.rejected().end());
      continue;
    }
    // Nothing passes: the kept terms are revisited, each way below in turn; a change is a round
    // of its own (the round's refusals go with it), and the loop goes on.
    const auto revisited = [&](bool enabled, const auto& change) {
      if (kept || !enabled) return false;
      loop_steps::Round revisit(context, round, &r);
      if (!change(revisit)) return false;
      if (backward_after_revisits) revisit.backward_pass();
      auto& refused = r.rounds.back().rejected;
      refused.insert(refused.begin(), step.rejected().begin(), step.rejected().end());
      return true;
    };
    // A kept term's parameters, estimated while other effects were still in the residual, are
    // estimated again with the model's other terms (Round::refine_parameters).
    if (revisited(options.refine_parameters,
                  [&](loop_steps::Round& x) { return x.refine_parameters(dxs); }))
      continue;
    // A kept term chosen while other effects were still in the residual may give way to what the
    // model without it ranks first (Round::exchange).
    if (revisited(options.exchange_terms && exchanges < loop_steps::kExchanges,
                  [&](loop_steps::Round& x) { return x.exchange(round_options, &taken_out); })) {
      ++exchanges;
      continue;
    }
    // Nothing kept changes: a kept product whose factor earns no place is written without it
    // (Round::drop_idle_factors).
    if (revisited(options.drop_idle_factors,
                  [](loop_steps::Round& x) { return x.drop_idle_factors(); }))
      continue;
    // Nothing kept changes: a kept term whose field scales with a channel the flights hold nearly
    // steady is written as that product (Round::steady_factor_in_place).
    if (revisited(options.steady_factor_products,
                  [](loop_steps::Round& x) { return x.steady_factor_in_place(); }))
      continue;
    // Nothing kept changes: a kept term that a look-alike beats with every other term in place
    // gives way to it (Round::better_look_alike_in_place).
    if (revisited(options.better_look_alike,
                  [](loop_steps::Round& x) { return x.better_look_alike_in_place(); }))
      continue;
    // Nothing kept changes: a kept term that another kept term makes redundant once that term's
    // parameters are estimated again without it leaves (Round::redundant_once_refined).
    if (revisited(options.redundant_once_refined,
                  [&](loop_steps::Round& x) { return x.redundant_once_refined(&dropped_refined); }))
      continue;
    const auto& rejected = step.rejected();
    if (!kept) {
      if (const std::string dropped = chance_drifts_dropped(); !dropped.empty()) {
        finish(without_chance_drifts(dropped));
        break;
      }
      if (rejected.empty()) {
        finish(verdict);
      } else {
        std::string reason = eligible.empty() ? verdict + "; " : "";
        reason += "no term passes: ";
        for (size_t k = 0; k < rejected.size(); ++k) {
          reason += (k ? "; " : "") + rejected[k].first + ": " + rejected[k].second;
        }
        finish(reason + ": stopped");
      }
      break;
    }
  }
  // The lines size nothing in a model without slow terms: its file does not list them.
  if (lines_fallback && r.model.slow_terms.empty()) r.model.fit.slow_lines.clear();
  loop_steps::record_displaced_lags(start, &r.rounds);
  return r;
}

}  // namespace magcomp
