// magcomp: diagnose_loop's step for the channel that predicts most of what remains: its plain
// field term, the whole model fitted again (Round::named_channel_term, loop_round.h).
#include <cstdio>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "loop_round.h"
#include "loop_steps.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/model/term.h"

namespace magcomp::loop_steps {

bool Round::named_channel_term(const std::vector<Diagnosis>& dxs,
                               std::set<std::string>* named_channels) {
  if (!c_.options.named_channel_term) return false;
  // The first flight whose residual is predictable, and the channel its flexible model of all
  // channels leans on most (ExplainableShare::channels), when that stands above the noise floor.
  size_t flight = 0;
  while (flight + 1 < dxs.size() && dxs[flight].explainable.within_noise) ++flight;
  const ExplainableShare& ex = dxs[flight].explainable;
  if (ex.within_noise || ex.channels.empty() || !(ex.channels.front().second > ex.noise_floor))
    return false;
  const std::string& channel = ex.channels.front().first;
  // A state of the aircraft only: a residual that follows position or motion first is leakage.
  if (!is_aircraft_state(channel) || !named_channels->insert(channel).second) return false;
  // The search scores a candidate beside the base's columns as they stand: TL's exact-norm
  // column (`norm`) is the remainder of the base's own TL coefficients, which the candidate's fit
  // does not move. A channel whose field TL's coefficients had partly taken (a servo's current
  // that follows the yaw rate through the maneuvers) then ranks far down, while the fitted model
  // with it, TL's remainder computed again, leaves a fraction of the error. Fitted here as every
  // kept term is (fit_model).
  const TermSpec plain("field:" + channel);
  Model next = r_->model;
  if (!next.add_term(plain)) return false;
  const LoopRound& now = r_->rounds.back();
  // At the model's ridge strength, and with the ridge weakened with it (better_lambda, from the
  // start model's strength down to a thousandth): a term TL's columns had partly stood in for
  // leaves them to be fitted again, and the ridge that held them may hold them still. Kept as a
  // new term is kept: the held-out error falls by the accepted share and the resolution, and
  // neither half rises.
  std::optional<std::pair<Model, LoopRound>> best;
  LoopRound at_model_lambda;
  try {
    auto fitted = fit_score(next);
    at_model_lambda = fitted.second;
    if (improves_on(fitted.second, now)) best = std::move(fitted);
  } catch (const Error&) {
  }
  if (auto ridge = better_lambda(next, c_.start.fit.lambda, now, c_.flights, c_.truth, c_.held_out,
                                 c_.validation, c_.options)) {
    if (!best || ridge->second.heldout_std_nT < best->second.heldout_std_nT) best = ridge;
  }
  if (!best) {
    char why[300];
    std::snprintf(why, sizeof(why),
                  "the channel that predicts most of what remains; fitted with the model it "
                  "leaves %.4f nT held out (halves %.4f, %.4f) against %.4f (%.4f, %.4f), at "
                  "fit.lambda %.3g and with a weaker ridge: not the accepted share, the "
                  "resolution and both halves",
                  at_model_lambda.heldout_std_nT, at_model_lambda.selection_std_nT,
                  at_model_lambda.confirmation_std_nT, now.heldout_std_nT, now.selection_std_nT,
                  now.confirmation_std_nT, r_->model.fit.lambda);
    refuse(plain.text(), why);
    return false;
  }
  LoopRound lr = std::move(best->second);
  lr.round = round_;
  lr.added = plain.text();
  lr.explained = variance_share(lr.heldout_std_nT, now.heldout_std_nT);
  if (best->first.fit.lambda != r_->model.fit.lambda) {
    char change[160];
    std::snprintf(change, sizeof(change), "fit.lambda %.3g with it (was %.3g)",
                  best->first.fit.lambda, r_->model.fit.lambda);
    lr.model_change = change;
  }
  keep(std::move(best->first), std::move(lr));
  return true;
}

}  // namespace magcomp::loop_steps
