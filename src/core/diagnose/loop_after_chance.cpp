// magcomp: what the model took in with or after a drift the chance control takes out, judged
// again without it (loop_round.h: Round::shed_after_chance_drift).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>

#include "loop_round.h"
#include "magcomp/core/error.h"

namespace magcomp::loop_steps {

namespace {

bool has_term(const Model& m, const std::string& text) {
  return std::find(m.terms.begin(), m.terms.end(), text) != m.terms.end();
}

}  // namespace

int Round::shed_after_chance_drift(const std::string& drift) {
  // The round that took the drift in.
  size_t k = r_->rounds.size();
  for (bool found = false; !found && k-- > 1;) {
    const std::vector<std::string> added = step_terms(r_->rounds[k].added);
    found = std::find(added.begin(), added.end(), drift) != added.end();
  }
  if (k == 0 || k >= r_->rounds.size()) return 0;
  // What that round took in beside it, and what later rounds took in: each was sized with the
  // drift in place. The round that wrote TL as the exact norm, if one of these.
  const std::vector<std::string> beside = step_terms(r_->rounds[k].added);
  std::vector<std::string> sized_with;  // in the order taken in
  size_t norm_round = 0;
  for (size_t j = k; j < r_->rounds.size(); ++j)
    for (const std::string& t : step_terms(r_->rounds[j].added)) {
      if (t == drift || t.empty()) continue;
      if (t == "norm") norm_round = j;
      if (std::find(sized_with.begin(), sized_with.end(), t) == sized_with.end())
        sized_with.push_back(t);
    }
  if (sized_with.empty()) return 0;
  int shed = 0;
  for (;;) {
    const LoopRound& now = r_->rounds.back();
    const Model& model = r_->model;
    std::optional<std::pair<Model, LoopRound>> best;
    std::string best_what;
    const auto consider = [&](Model m, const std::string& what) {
      try {
        auto scored = fit_score(std::move(m));
        const double nT = scored.second.heldout_std_nT;
        if (!std::isfinite(nT) || !(nT < now.heldout_std_nT)) return;
        if (best && !(nT < best->second.heldout_std_nT)) return;
        best.emplace(std::move(scored));
        best_what = what;
      } catch (const Error&) {
        // the model without it does not fit: it stays
      }
    };
    // TL's exact norm taken in with or after the drift: the norm (and the bias of its fit
    // against the reference) out, the fit's method and ridge strength as before that round.
    if (norm_round > 0 && has_term(model, "norm") && !has_term(c_.start, "norm")) {
      Model m = model;
      std::string what;
      for (const std::string t : {"bias", "norm"}) {
        if (!has_term(model, t) || has_term(c_.start, t) ||
            std::find(sized_with.begin(), sized_with.end(), t) == sized_with.end())
          continue;
        m.terms.erase(std::remove(m.terms.begin(), m.terms.end(), t), m.terms.end());
        what += (what.empty() ? "" : " + ") + t;
      }
      m.fit.method = c_.start.fit.method;
      // The slow stage is still fitted against the reference (Model::slow_terms).
      if (m.slow_terms.empty()) m.fit.reference = c_.start.fit.reference;
      const double lambda_before = r_->rounds[norm_round - 1].lambda;
      if (std::isfinite(lambda_before)) m.fit.lambda = lambda_before;
      m.coefficients.resize(0);
      consider(std::move(m), what);
    }
    // Each other term so taken in.
    for (const std::string& t : sized_with) {
      if (t == "norm" || t == "bias" || !has_term(model, t) || !removable(c_.start, TermSpec(t)))
        continue;
      consider(without_term(model, TermSpec(t)), t);
    }
    if (!best) return shed;
    const bool together = std::find(beside.begin(), beside.end(), best_what) != beside.end() ||
                          (best_what.find("norm") != std::string::npos && norm_round == k);
    char why[400];
    std::snprintf(why, sizeof(why),
                  "taken in %s %s, which the flight cannot tell from chance, and sized with it "
                  "in place; without it too the held-out error %.4f -> %.4f nT",
                  together ? "together with" : "after", drift.c_str(), now.heldout_std_nT,
                  best->second.heldout_std_nT);
    LoopRound& last = r_->rounds.back();
    last.removed.emplace_back(best_what, why);
    take_scores(best->second, &last);
    r_->model = std::move(best->first);
    ++shed;
  }
}

}  // namespace magcomp::loop_steps
