// magcomp: a kept term of a round of diagnose_loop giving way to one of its look-alikes
// (loop_round.h): the look-alikes of a kept term, and the swap when one does better with every
// other term in place.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>

#include "loop_round.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/math/correlation.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {

namespace {

// `e` with its source k read through `channel` in its place (a shorthand keeps its own spelling).
std::string with_source(const ExprTerm& e, size_t k, const std::string& channel) {
  const std::string alias = e.spec();
  if (e.signal().sources.size() == 1 && alias.find(':') != std::string::npos &&
      (alias.rfind("current:", 0) == 0 || alias.rfind("dcurrent:", 0) == 0 ||
       alias.rfind("rate:", 0) == 0))
    return alias.substr(0, alias.find(':') + 1) + channel;
  SignalExpr signal = e.signal();
  signal.sources[k] = channel;
  const char* projection = e.projection() == Projection::Field     ? "field:"
                           : e.projection() == Projection::Induced ? "induced:"
                                                                   : "scalar:";
  return projection + signal.str();
}

}  // namespace

std::vector<std::string> Round::look_alikes_of(const TermSpec& t,
                                               const std::set<std::string>& model_fields) const {
  std::vector<std::string> out;
  const auto add = [&](const std::string& spec) {
    if (spec != t.text() && std::find(out.begin(), out.end(), spec) == out.end())
      out.push_back(spec);
  };
  // The look-alikes the rounds listed beside a term of the same channels (a kept term's
  // parameters may have been estimated again since: its channels still name it).
  const std::set<std::string> fields = fields_of(t);
  for (const LoopRound& lr : r_->rounds) {
    if (lr.look_alikes.empty() || lr.together || lr.black_box) continue;
    if (fields_of(TermSpec(lr.added)) != fields) continue;
    for (const auto& [term, heldout_nT] : lr.look_alikes) add(term);
  }
  // The same term through each recorded state or angular rate that moves with one of its
  // channels on every flight (|r| >= kLookAlikeCorrelation): what a round kept beside another
  // term, in a set or while other effects were still in the residual was never compared with
  // them.
  const ExprTerm* e = t.expr();
  if (!e) return out;
  const std::vector<std::string>& sources = e->signal().sources;
  for (size_t k = 0; k < sources.size(); ++k) {
    if (!fields.count(sources[k])) continue;  // B or Bt: no channel
    std::vector<std::string> alike;
    bool first = true;
    for (const FlightData* f : c_.flights) {
      if (!f->has(sources[k])) return out;
      const Eigen::VectorXd x = f->column(sources[k]);
      std::vector<std::string> here;
      for (const std::string& y : source_fields(c_.start, *f, c_.truth, false, nullptr)) {
        if (y == sources[k] || model_fields.count(y) || is_position_channel(y) ||
            is_earth_frame_velocity(y) ||
            (!first && std::find(alike.begin(), alike.end(), y) == alike.end()))
          continue;
        const double r = pearson_where_finite(x, f->column(y),
                                              static_cast<Eigen::Index>(kLookAlikeRatioMinSamples));
        if (std::abs(r) >= kLookAlikeCorrelation) here.push_back(y);
      }
      alike = std::move(here);
      first = false;
    }
    for (const std::string& y : alike) add(with_source(*e, k, y));
  }
  return out;
}

bool Round::better_look_alike_in_place() {
  const LoopRound now = r_->rounds.back();
  const Model& model = r_->model;
  const std::set<std::string> model_fields = fields_of(model);  // what the terms read
  struct Best {
    std::pair<Model, LoopRound> fitted;
    std::string old_text, new_text;
  };
  std::optional<Best> best;
  for (const TermSpec& t : model.terms) {
    // A slow term's look-alike takes its place in the slow list (with_term_as): the slow stage
    // sizes it where it sized the kept term.
    if (!revisable(c_.start, model, t, c_.options.slow_look_alikes) || fields_of(t).empty())
      continue;
    for (const std::string& a : look_alikes_of(t, model_fields)) {
      try {
        const std::set<std::string> fields = fields_of(TermSpec(a));
        // A channel another kept term reads already is not a name of its own.
        if (fields.empty() || std::any_of(fields.begin(), fields.end(), [&](const std::string& x) {
              return model_fields.count(x) > 0 && !fields_of(t).count(x);
            }))
          continue;
        auto fitted = fit_score(with_term_as(model, t.text(), a));
        const LoopRound& lr = fitted.second;
        // A swap renames the effect: the look-alike earns it as a parameter estimated again
        // does (improves_in_place: the accepted share of the held-out variance, neither half
        // worse); a tie keeps the name the round chose.
        if (!improves_in_place(lr, now) || !holds_where_sized(lr, now)) continue;
        if (best && !(lr.heldout_std_nT < best->fitted.second.heldout_std_nT)) continue;
        best.emplace(Best{std::move(fitted), t.text(), a});
      } catch (const Error&) {
      }
    }
  }
  if (!best) return false;
  const LoopRound& lr = best->fitted.second;
  char why[300];
  std::snprintf(why, sizeof(why),
                "a look-alike of it does better with every other term in place: held-out error "
                "%.4f -> %.4f nT (halves %.4f -> %.4f, %.4f -> %.4f)",
                now.heldout_std_nT, lr.heldout_std_nT, now.selection_std_nT, lr.selection_std_nT,
                now.confirmation_std_nT, lr.confirmation_std_nT);
  replaced_as_round(std::move(best->fitted), best->old_text, best->new_text, why);
  return true;
}

}  // namespace magcomp::loop_steps
