// magcomp: the diagnose -> add -> refit loop.
#include "magcomp/core/diagnose/diagnose_loop.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <set>

#include "loop_steps.h"
#include "magcomp/core/diagnose/diagnose_season.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {

using loop_steps::add_candidate_term;
using loop_steps::better_lambda;
using loop_steps::Eligible;
using loop_steps::eligible_candidates;
using loop_steps::HeldOut;
using loop_steps::learned_law;
using loop_steps::refusal;
using loop_steps::removable;
using loop_steps::score;
using loop_steps::variance_share;
using loop_steps::without_term;

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
  constexpr size_t kTriesPerRound = 3;
  std::set<std::string> learned_channels;  // one learned law per channel
  LoopResult r;
  r.model = start;
  if (!r.model.fitted()) fit_model(r.model, flights);
  std::vector<HeldOut> held_out(flights.size());  // each flight's held-out samples, in two halves
  for (int round = 1;; ++round) {
    std::vector<Diagnosis> dxs;
    const auto diagnose_all = [&] {
      dxs.clear();
      for (size_t f = 0; f < flights.size(); ++f)
        dxs.push_back(diagnose(r.model, *flights[f], truth, options));
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
    std::vector<Eligible> eligible = eligible_candidates(dxs, min_share);
    std::optional<Eligible> within_span;
    if (options.ridge_for_span_terms && !eligible.empty() &&
        eligible.front().base_span_share >= loop_steps::kWithinSpanShare)
      within_span = eligible.front();
    if ((options.choose_lambda || within_span) && round <= max_rounds) {
      if (auto step = better_lambda(r.model, start.fit.lambda, r.rounds.back(), flights, truth,
                                    held_out, validation, options)) {
        LoopRound lr = std::move(step->second);
        char added[64];
        std::snprintf(added, sizeof(added), "fit.lambda %.3g", step->first.fit.lambda);
        lr.round = round;
        lr.added = added;
        lr.explained = variance_share(lr.heldout_std_nT, r.rounds.back().heldout_std_nT);
        lr.regularisation = true;
        if (within_span) {
          lr.in_place_of = within_span->term;
          lr.in_place_of_span_share = within_span->base_span_share;
        }
        r.rounds.push_back(std::move(lr));
        r.model = std::move(step->first);
        diagnose_all();
        eligible = eligible_candidates(dxs, min_share);
      }
    }
    for (size_t f = 0; on_round && f < flights.size(); ++f) on_round(round, f, dxs[f]);
    const Diagnosis& dx = dxs.front();
    // Over several flights, what is said of them together.
    const std::string verdict = flights.size() == 1 ? dx.verdict : merge_diagnoses(dxs).verdict;
    const auto finish = [&](std::string reason) {
      r.stop_reason = std::move(reason);
      r.last = dxs.front();
      r.last_flights = std::move(dxs);
    };
    if (round > max_rounds) {
      finish("stopped after " + std::to_string(max_rounds) + " rounds; " + verdict);
      break;
    }
    // Fits `next` and keeps it if it passes every check; else records why in `rejected`.
    std::vector<std::pair<std::string, std::string>> rejected;
    auto try_model = [&](Model next, const std::string& added, double explained, bool black_box) {
      next.coefficients.resize(0);
      fit_model(next, flights);
      LoopRound lr = score(next, flights, truth, held_out, validation);
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
      fit_model(m, flights);
      LoopRound lr = score(m, flights, truth, held_out, validation);
      return std::make_pair(std::move(m), std::move(lr));
    };
    // On each half of the held-out lines, as a term of the search is accepted on each split:
    // the accepted share of the variance and the resolution of the std.
    const auto passes = [&](double with_nT, double without_nT) {
      return variance_share(with_nT, without_nT) >= options.accept_fraction &&
             without_nT - with_nT >= options.resolution_nT;
    };
    // Whether a pair fitted together (`lr`) passes the checks a pair must: every check of a
    // single term, the accepted share and the resolution on each half of the held-out lines, and
    // each of its terms needed (the pair lowers the error variance of each alone by the accepted
    // share).
    const auto pair_passes = [&](const LoopRound& lr, const LoopRound& alone_a,
                                 const LoopRound& alone_b) {
      const LoopRound& now = r.rounds.back();
      return refusal(lr, now).empty() && passes(lr.selection_std_nT, now.selection_std_nT) &&
             passes(lr.confirmation_std_nT, now.confirmation_std_nT) &&
             variance_share(lr.heldout_std_nT, alone_a.heldout_std_nT) >= options.accept_fraction &&
             variance_share(lr.heldout_std_nT, alone_b.heldout_std_nT) >= options.accept_fraction;
    };
    // Keeps a pair fitted together as this round.
    const auto keep_pair = [&](std::pair<Model, LoopRound> fitted, const std::string& a,
                               const std::string& b, double alone_a_nT, double alone_b_nT) {
      LoopRound lr = std::move(fitted.second);
      lr.round = round;
      lr.added = a + " + " + b;
      lr.explained = variance_share(lr.heldout_std_nT, r.rounds.back().heldout_std_nT);
      lr.together = true;
      lr.alone_std_nT = {alone_a_nT, alone_b_nT};
      lr.rejected = std::move(rejected);
      rejected.clear();
      r.rounds.push_back(std::move(lr));
      r.model = std::move(fitted.first);
    };
    bool kept = false;
    // A lag ranked first by the share it explains with the channel term it was judged with
    // (Candidate::partner), but not eligible alone: the two together, kept if they pass a pair's
    // checks and lower the held-out error below the first single term that passes (a scalar
    // lag delays every channel's signature; a delayed channel term stands in for it on that
    // channel only).
    if (options.joint_steps) {
      std::optional<std::pair<Model, LoopRound>> partnered;
      std::string partnered_a, partnered_b;
      double partnered_alone[2] = {NAN, NAN};
      for (const Diagnosis& d : dxs) {
        if (d.candidates.empty()) continue;
        const Candidate& top = d.candidates.front();
        if (top.partner.empty() || (top.accepted && top.explained_fraction >= min_share)) continue;
        try {
          Model with_a = r.model, with_b = r.model, with_both = r.model;
          add_candidate_term(top.term, top.slow, truth, &with_a);
          add_candidate_term(top.partner, false, truth, &with_b);
          add_candidate_term(top.term, top.slow, truth, &with_both);
          add_candidate_term(top.partner, false, truth, &with_both);
          const LoopRound alone_a = fit_score(std::move(with_a)).second;
          const LoopRound alone_b = fit_score(std::move(with_b)).second;
          auto both = fit_score(std::move(with_both));
          if (!pair_passes(both.second, alone_a, alone_b)) continue;
          if (partnered && !(both.second.heldout_std_nT < partnered->second.heldout_std_nT))
            continue;
          partnered.emplace(std::move(both));
          partnered_a = top.term;
          partnered_b = top.partner;
          partnered_alone[0] = alone_a.heldout_std_nT;
          partnered_alone[1] = alone_b.heldout_std_nT;
        } catch (const Error&) {
        }
      }
      if (partnered) {
        double single_nT = INFINITY;  // the first single term that passes
        for (size_t k = 0; k < eligible.size() && k < kTriesPerRound; ++k) {
          Model next = r.model;
          add_candidate_term(eligible[k].term, eligible[k].slow, truth, &next);
          const LoopRound lr = fit_score(std::move(next)).second;
          if (refusal(lr, r.rounds.back()).empty()) {
            single_nT = lr.heldout_std_nT;
            break;
          }
        }
        if (partnered->second.heldout_std_nT < single_nT) {
          keep_pair(std::move(*partnered), partnered_a, partnered_b, partnered_alone[0],
                    partnered_alone[1]);
          kept = true;
        }
      }
    }
    // The accepted candidates in rank order: the first that passes every check is kept.
    for (size_t k = 0; k < eligible.size() && k < kTriesPerRound && !kept; ++k) {
      Model next = r.model;
      add_candidate_term(eligible[k].term, eligible[k].slow, truth, &next);
      kept = try_model(std::move(next), eligible[k].term, eligible[k].explained, false);
    }
    // Effects that act together: when no term passes alone while the residual stays
    // predictable, pairs of terms of distinct channels, fitted together. A pair is kept if it
    // passes every check, lowers the error on each half of the held-out lines by the accepted
    // share and the resolution, and each of its terms lowers the pair's error variance by the
    // accepted share (each is needed); at least one of them must fail alone (else it is the
    // single step's business). The best such pair by held-out error.
    const bool predictable = std::any_of(
        dxs.begin(), dxs.end(), [](const Diagnosis& d) { return !d.explainable.within_noise; });
    if (options.joint_steps && !kept && predictable) {
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
      for (const Diagnosis& d : dxs) {
        const ExplainableShare& ex0 = d.explainable;
        if (ex0.within_noise) continue;
        for (size_t k = 0; k < ex0.channels.size() && k < kResidualChannels; ++k) {
          const std::string& channel = ex0.channels[k].first;
          const auto first = std::find_if(d.candidates.begin(), d.candidates.end(),
                                          [&](const Candidate& c) { return c.channel == channel; });
          if (first == d.candidates.end()) continue;
          Candidate plain;
          plain.term = (is_electrical(channel) ? "current:" : "field:") + channel;
          plain.channel = channel;
          take(plain);
          take(*first);
        }
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
          if (!pair_passes(lr, alone[a], alone[b])) continue;
          if (lr.heldout_std_nT < best_std) {
            best_std = lr.heldout_std_nT;
            best.emplace(std::move(fitted), std::move(lr));
            best_a = a;
            best_b = b;
          }
        }
      }
      if (best) {
        keep_pair(std::move(*best), pool[best_a].term, pool[best_b].term,
                  alone[best_a].heldout_std_nT, alone[best_b].heldout_std_nT);
        kept = true;
      }
    }
    // When no term of the language passes while the residual stays predictable: a learned law
    // of the channel that predicts most of it, if that is a current or a voltage (a residual
    // that follows position or motion first is leakage, not a law), under the same checks.
    // The flight whose residual is predictable (the first such), and its data.
    size_t law_flight = 0;
    while (law_flight + 1 < dxs.size() && dxs[law_flight].explainable.within_noise) ++law_flight;
    const Diagnosis& law_dx = dxs[law_flight];
    const ExplainableShare& ex = law_dx.explainable;
    if (!kept && !ex.within_noise && !ex.channels.empty() &&
        ex.channels.front().second > ex.noise_floor &&
        learned_channels.insert(ex.channels.front().first).second) {
      const std::string& channel = ex.channels.front().first;
      const double share = ex.channels.front().second;
      const Candidate* shape = nullptr;  // the best ranked one-channel term of the channel
      for (const Candidate& c : law_dx.candidates) {
        const auto e = c.channel == channel ? parse_expr_term(c.term) : nullptr;
        if (e && e->signal().sources.size() == 1) {
          shape = &c;
          break;
        }
      }
      const std::vector<std::string> law =
          learned_law(channel, shape, r.model, *flights[law_flight]);
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
  return r;
}

}  // namespace magcomp
