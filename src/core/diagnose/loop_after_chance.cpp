// magcomp: what a set accepted together keeps once the chance control takes its drift out
// (loop_round.h: Round::shed_beside_chance_drift).
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

int Round::shed_beside_chance_drift(const std::string& drift) {
  // The round that took the drift in, and the one before it (the model it was added to).
  std::vector<std::string> beside;
  size_t k = r_->rounds.size();
  while (k-- > 1) {
    beside = step_terms(r_->rounds[k].added);
    if (std::find(beside.begin(), beside.end(), drift) != beside.end()) break;
  }
  if (k == 0 || k >= r_->rounds.size()) return 0;
  if (beside.size() < 2) return 0;  // taken in alone: nothing came with it
  const double lambda_before = r_->rounds[k - 1].lambda;
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
    // TL's exact norm taken in with the drift: the norm (and the bias of its fit against the
    // reference) out, the fit's method and ridge strength as before that round.
    const bool norm_beside =
        std::find(beside.begin(), beside.end(), "norm") != beside.end() && has_term(model, "norm");
    if (norm_beside) {
      Model m = model;
      std::string what;
      for (const std::string t : {"bias", "norm"}) {
        if (!has_term(model, t) || has_term(c_.start, t) ||
            std::find(beside.begin(), beside.end(), t) == beside.end())
          continue;
        m.terms.erase(std::remove(m.terms.begin(), m.terms.end(), t), m.terms.end());
        what += (what.empty() ? "" : " + ") + t;
      }
      m.fit.method = c_.start.fit.method;
      // The slow stage is still fitted against the reference (Model::slow_terms).
      if (m.slow_terms.empty()) m.fit.reference = c_.start.fit.reference;
      if (std::isfinite(lambda_before)) m.fit.lambda = lambda_before;
      m.coefficients.resize(0);
      consider(std::move(m), what);
    }
    // Each other term taken in with it.
    for (const std::string& t : beside) {
      if (t == drift || t == "norm" || t == "bias" || !has_term(model, t) ||
          !removable(c_.start, TermSpec(t)))
        continue;
      consider(without_term(model, TermSpec(t)), t);
    }
    if (!best) return shed;
    char why[400];
    std::snprintf(why, sizeof(why),
                  "taken in together with %s, which the flight cannot tell from chance; "
                  "without it too the held-out error %.4f -> %.4f nT",
                  drift.c_str(), now.heldout_std_nT, best->second.heldout_std_nT);
    LoopRound& last = r_->rounds.back();
    last.removed.emplace_back(best_what, why);
    take_scores(best->second, &last);
    r_->model = std::move(best->first);
    ++shed;
  }
}

}  // namespace magcomp::loop_steps
