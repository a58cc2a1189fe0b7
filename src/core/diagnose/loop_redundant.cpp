// magcomp: a kept term of a round of diagnose_loop leaving (loop_round.h): one that another kept
// term, its parameters estimated again without it, makes redundant, and the backward pass (one
// that later terms make redundant as they stand).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>

#include "loop_round.h"
#include "magcomp/core/error.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {

bool Round::redundant_once_refined(std::set<std::string>* dropped) {
  const LoopRound now = r_->rounds.back();
  const Model& model = r_->model;
  const double accept = c_.options.accept_fraction;
  struct Best {
    std::pair<Model, LoopRound> fitted;
    std::string dropped_text, old_text, new_text;
  };
  std::optional<Best> best;
  const auto listed = [](const std::vector<std::string>& list, const std::string& t) {
    return std::find(list.begin(), list.end(), t) != list.end();
  };
  for (const TermSpec& t : model.terms) {
    if (!removable(c_.start, t) || fields_of(t).empty() ||
        listed(model.black_box_terms, t.text()) || dropped->count(t.text()))
      continue;
    const Model without = without_term(model, t);
    // Each other kept term with its parameters estimated again: (index in `without`, spec).
    std::vector<std::pair<size_t, std::string>> again;
    for (size_t k = 0; k < without.terms.size(); ++k) {
      const TermSpec& u = without.terms[k];
      const bool slow = listed(without.slow_terms, u.text());
      if (slow && (!u.expr() || !removable(c_.start, u) || fields_of(u).empty() ||
                   listed(without.black_box_terms, u.text())))
        continue;
      const std::string spec =
          slow ? retimed_slow_term(without, k) : freed_parameters(without, k, c_.start);
      if (!spec.empty()) again.emplace_back(k, spec);
    }
    for (const auto& [k, spec] : again) {
      try {
        auto fitted = fit_score(with_term_as(without, without.terms[k].text(), spec));
        const LoopRound& lr = fitted.second;
        // The term leaves only when it explains neither the accepted share of the held-out
        // variance nor the resolution against that model: a slow term's time constant estimated
        // again may write much of another slow term over one flight, not all of it.
        if (!std::isfinite(lr.heldout_std_nT) ||
            variance_share(now.heldout_std_nT, lr.heldout_std_nT) >= accept ||
            lr.heldout_std_nT - now.heldout_std_nT >= c_.options.resolution_nT)
          continue;  // the term still earns its place
        if (std::isfinite(now.validation_std_nT) &&
            variance_share(now.validation_std_nT, lr.validation_std_nT) >= accept)
          continue;
        if (raises_calibration_rows(lr, now, c_.options.resolution_nT)) continue;
        const std::string new_text = fitted.first.terms[k].text();
        if (new_text == without.terms[k].text()) continue;  // the same parameters: backward_pass
        if (best && !(lr.heldout_std_nT < best->fitted.second.heldout_std_nT)) continue;
        best.emplace(Best{std::move(fitted), t.text(), without.terms[k].text(), new_text});
      } catch (const Error&) {
      }
    }
  }
  if (!best) return false;
  LoopRound lr = std::move(best->fitted.second);
  lr.round = round_;
  lr.added = best->new_text;
  lr.explained = variance_share(lr.heldout_std_nT, now.heldout_std_nT);
  char why[300];
  std::snprintf(why, sizeof(why),
                "its parameters estimated again without %s: held-out error %.4f -> %.4f nT",
                best->dropped_text.c_str(), now.heldout_std_nT, lr.heldout_std_nT);
  lr.replaced.emplace_back(best->old_text, why);
  std::snprintf(why, sizeof(why),
                "made redundant by %s, its parameters estimated again: without it the held-out "
                "error %.4f -> %.4f nT",
                best->new_text.c_str(), now.heldout_std_nT, lr.heldout_std_nT);
  lr.removed.emplace_back(best->dropped_text, why);
  dropped->insert(best->dropped_text);
  keep(std::move(best->fitted.first), std::move(lr));
  return true;
}

void Round::backward_pass() {
  if (r_->rounds.size() < 2) return;
  const double accept = c_.options.accept_fraction;
  const LoopRound before = r_->rounds[r_->rounds.size() - 2];
  const std::vector<std::string> now_terms = step_terms(r_->rounds.back().added);
  const std::set<std::string> added_now(now_terms.begin(), now_terms.end());  // this round's
  for (;;) {
    const LoopRound& now = r_->rounds.back();
    std::optional<std::pair<Model, LoopRound>> drop;
    std::string drop_term;
    double drop_share = INFINITY;
    for (const TermSpec& t : r_->model.terms) {
      if (!removable(c_.start, t) || added_now.count(t.text())) continue;
      auto [m, lr] = fit_score(without_term(r_->model, t));
      // The share of the variance the term still explains: what its leaving would add.
      const double share = variance_share(now.heldout_std_nT, lr.heldout_std_nT);
      // It leaves when it would not be added to the model without it (or, lenient, when it
      // explains under a quarter of the accepted share).
      const double leave = c_.options.backward_at_acceptance ? accept : 0.25 * accept;
      const bool needed = c_.options.backward_at_acceptance
                              ? share >= accept && lr.heldout_std_nT - now.heldout_std_nT >=
                                                       c_.options.resolution_nT
                              : share >= leave;
      const bool validation_ok =
          !std::isfinite(now.validation_std_nT) ||
          variance_share(now.validation_std_nT, lr.validation_std_nT) < leave;
      if (!needed && validation_ok && lr.heldout_std_nT < before.heldout_std_nT &&
          share < drop_share) {
        drop_share = share;
        drop_term = t.text();
        drop.emplace(std::move(m), std::move(lr));
      }
    }
    if (!drop) break;
    char why[200];
    std::snprintf(why, sizeof(why),
                  "made redundant by later terms: without it the held-out error %.4f -> %.4f nT",
                  now.heldout_std_nT, drop->second.heldout_std_nT);
    LoopRound& last = r_->rounds.back();
    last.removed.emplace_back(drop_term, why);
    take_scores(drop->second, &last);
    r_->model = std::move(drop->first);
  }
}

}  // namespace magcomp::loop_steps
