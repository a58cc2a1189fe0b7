// magcomp: a kept term of a round of diagnose_loop giving way to its product with a channel the
// flights hold nearly steady (loop_round.h): the factor the rounds table lists under "may scale
// with a steady ...", tried in place once every other effect is written.
#include <algorithm>
#include <cstdio>
#include <optional>
#include <set>

#include "loop_round.h"
#include "magcomp/core/error.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {

namespace {

// Transforms after which a product still reads as the term scaled by the factor: linear in the
// signal (a low-pass, a derivative, a delay, ...) or |x| of a positive factor. A threshold, a
// play or a saturation of the product would move with the factor's level instead.
bool scales_through(const SignalExpr& signal) {
  return std::all_of(signal.transforms.begin(), signal.transforms.end(), [](const Transform& t) {
    switch (t.kind) {
      case TransformKind::Derivative:
      case TransformKind::Integral:
      case TransformKind::Abs:
      case TransformKind::LowPass:
      case TransformKind::HighPass:
      case TransformKind::Delay:
        return true;
      default:
        return false;
    }
  });
}

// `e` (a field of one recorded channel) times `factor`: field:x*f with e's transforms; "" when
// the product would not read as e scaled by f.
std::string times_factor(const ExprTerm& e, const std::string& factor) {
  if (e.projection() != Projection::Field) return "";
  SignalExpr signal = e.signal();
  if (signal.sources.size() != 1 || !scales_through(signal)) return "";
  signal.sources.push_back(factor);
  return "field:" + signal.str();
}

}  // namespace

bool Round::steady_factor_in_place() {
  const LoopRound now = r_->rounds.back();
  const Model& model = r_->model;
  const std::set<std::string> model_fields = fields_of(model);  // what the terms read
  struct Best {
    std::pair<Model, LoopRound> fitted;
    std::string old_text, new_text, factor;
    bool paired = false;  // a factor the search paired with the term, not one held steady
  };
  std::optional<Best> best;
  for (const TermSpec& t : model.terms) {
    const ExprTerm* e = t.expr();
    // A term of one recorded channel added by the loop, not a learned law's hinge nor a slow
    // term (its stage and lines are sized for the term as it is).
    if (!e || !revisable(c_.start, model, t) || fields_of(t).size() != 1) continue;
    // The factors the rounds listed beside a term of this channel (a kept term's parameters may
    // have been estimated again since: its channel still names it), and every recorded state
    // the flights hold within kSteadyFactorRelative of its mean (a larger term's modulation by
    // it may exceed the resolution, and is no longer listed as unseen).
    const std::set<std::string> fields = fields_of(t);
    std::vector<std::string> factors;
    const auto add = [&](const std::string& name) {
      if (!model_fields.count(name) &&
          std::find(factors.begin(), factors.end(), name) == factors.end())
        factors.push_back(name);
    };
    for (const LoopRound& lr : r_->rounds) {
      if (lr.steady_factors.empty() || fields_of(TermSpec(lr.added)) != fields) continue;
      for (const auto& f : lr.steady_factors) add(f.first);
    }
    for (const auto& f : steady_factors(c_.flights, fields, c_.truth, 1.0, kSteadyFactorRelative))
      add(f.first);
    // And the states a product the round's search ranked with the term paired it with: on the
    // lines the term was chosen on, it was the simpler of the two.
    std::set<std::string> paired;
    for (const LoopRound& lr : r_->rounds) {
      if (lr.paired_factors.empty() || fields_of(TermSpec(lr.added)) != fields) continue;
      for (const std::string& f : lr.paired_factors) {
        if (std::find(factors.begin(), factors.end(), f) == factors.end()) paired.insert(f);
        add(f);
      }
    }
    for (const std::string& f : factors) {
      const std::string product = times_factor(*e, f);
      if (product.empty()) break;
      try {
        auto fitted = fit_score(with_term_as(model, t.text(), product));
        const LoopRound& lr = fitted.second;
        // The product passes refusal() and raises neither half; its factor earns its place
        // (factor_resolved, the test drop_idle_factors keeps it by), and it holds where the
        // term is sized.
        if (!refusal(lr, now, c_.options).empty() || !halves_hold(lr, now) ||
            !factor_resolved(lr, now) || !holds_where_sized(lr, now))
          continue;
        if (best && !(lr.heldout_std_nT < best->fitted.second.heldout_std_nT)) continue;
        best.emplace(Best{std::move(fitted), t.text(), product, f, paired.count(f) > 0});
      } catch (const Error&) {
      }
    }
  }
  if (!best) return false;
  const LoopRound& lr = best->fitted.second;
  char why[520];
  std::snprintf(why, sizeof(why),
                "its field scales with %s, %s: held-out error %.4f -> %.4f nT (halves %.4f -> "
                "%.4f, %.4f -> %.4f)",
                best->factor.c_str(),
                best->paired ? "which its round's search paired with it where the lines it was "
                               "chosen on could not tell them apart"
                             : "a channel these flights hold nearly steady",
                now.heldout_std_nT, lr.heldout_std_nT, now.selection_std_nT, lr.selection_std_nT,
                now.confirmation_std_nT, lr.confirmation_std_nT);
  replaced_as_round(std::move(best->fitted), best->old_text, best->new_text, why);
  return true;
}

}  // namespace magcomp::loop_steps
