// magcomp: TL written as the exact norm together with an effect's term, when neither passes alone
// (loop_round.h: Round::exact_norm_with_a_term).
#include <algorithm>
#include <cmath>
#include <optional>

#include "loop_round.h"
#include "magcomp/core/error.h"

namespace magcomp::loop_steps {

bool Round::exact_norm_with_a_term(const DiagnoseOptions& options) {
  // Each form of the exact norm (exact_norm_forms), fitted and scored alone; the one to
  // diagnose: fitted against the reference where the flights record it (the calibration rows
  // then size TL on the scalar itself, and an effect on those rows is what they need beside it),
  // else the norm under the model's own fit; the lowest held-out error among them.
  struct Form {
    std::pair<Model, LoopRound> alone;
    std::string change;
  };
  std::vector<Form> forms;
  for (auto& [m, change] : exact_norm_forms(r_->model, c_.flights, c_.truth)) {
    try {
      auto fitted = fit_score(std::move(m));
      if (std::isfinite(fitted.second.heldout_std_nT)) forms.push_back({std::move(fitted), change});
    } catch (const Error&) {
      // not a fit these flights allow: not a choice
    }
  }
  const Form* base = nullptr;
  for (const Form& f : forms) {
    const bool reference = !f.change.empty();
    const bool base_reference = base && !base->change.empty();
    if (base && base_reference && !reference) continue;
    if (base && base_reference == reference &&
        !(f.alone.second.heldout_std_nT < base->alone.second.heldout_std_nT))
      continue;
    base = &f;
  }
  if (!base) return false;
  std::vector<Diagnosis> dxs;
  for (const FlightData* f : c_.flights)
    dxs.push_back(diagnose(base->alone.first, *f, c_.truth, options));
  const std::vector<Eligible> eligible =
      eligible_candidates(dxs, c_.min_share, !c_.options.refuse_within_span_terms);
  // Each of its first candidates beside each form (the ridge strength a reference fit of TL
  // needs depends on what the calibration rows hold beside it).
  std::optional<std::pair<Model, LoopRound>> best;
  const Form* best_form = nullptr;
  double best_term_alone_nT = NAN;
  for (size_t k : single_tries(eligible)) {
    const Eligible& e = eligible[k];
    std::optional<LoopRound> term_alone;
    try {
      Model alone = r_->model;
      add_candidate_term(e.term, e.slow, c_.truth, &alone);
      term_alone = fit_score(std::move(alone)).second;
    } catch (const Error&) {
      continue;  // the term does not fit beside the model: not a pair to judge
    }
    for (const Form& f : forms) {
      try {
        Model with = f.alone.first;
        add_candidate_term(e.term, e.slow, c_.truth, &with);
        auto fitted = fit_score(std::move(with));
        // Each is needed: the pair beats the norm alone and the term alone by the accepted
        // share, each half by passes(), and every check of a single term.
        if (!pair_passes(fitted.second, f.alone.second, *term_alone)) continue;
        if (best && !(fitted.second.heldout_std_nT < best->second.heldout_std_nT)) continue;
        best.emplace(std::move(fitted));
        best_form = &f;
        best_term_alone_nT = term_alone->heldout_std_nT;
      } catch (const Error&) {
        // not a fit these flights allow beside this form
      }
    }
  }
  if (!best) return false;
  std::vector<std::string> terms;
  for (const TermSpec& t : best->first.terms)
    if (std::find(r_->model.terms.begin(), r_->model.terms.end(), t) == r_->model.terms.end())
      terms.push_back(t.text());
  const std::string change = best_form->change;
  keep_together(std::move(*best), terms,
                {best_form->alone.second.heldout_std_nT, best_term_alone_nT});
  r_->rounds.back().model_change =
      change.empty() ? "TL as the exact norm" : "TL as the exact norm; " + change;
  return true;
}

}  // namespace magcomp::loop_steps
