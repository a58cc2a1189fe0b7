// magcomp: the share of the held-out variance a term of recorded aircraft states explains by
// chance (internal to src/core/diagnose; loop_steps.h): the same search run with those states
// read shifted in time against the residual.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>

#include "loop_round.h"
#include "loop_steps.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/math/correlation.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp::loop_steps {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}  // namespace

bool shiftable_channel(const std::string& name, const Model& model, const std::string& truth) {
  return is_aircraft_state(name) && name != truth && name != model.scalar &&
         fields_of(model).count(name) == 0;
}

bool reads_shiftable_channels_only(const TermSpec& t, const Model& model,
                                   const std::string& truth) {
  const std::set<std::string> f = fields_of(t);
  return !f.empty() && std::all_of(f.begin(), f.end(), [&](const std::string& c) {
    return shiftable_channel(c, model, truth);
  });
}

FlightData with_states_shifted(const FlightData& data, const Model& model, const std::string& truth,
                               double fraction) {
  FlightData out = data;
  const Eigen::Index n = data.size();
  if (n < 2) return out;
  const Eigen::Index shift = static_cast<Eigen::Index>(std::llround(fraction * n)) % n;
  if (shift <= 0) return out;
  for (const std::string& name : data.names()) {
    if (!shiftable_channel(name, model, truth)) continue;
    const FlightData::Column x = data.column(name);
    Eigen::VectorXd y(n);
    y.tail(n - shift) = x.head(n - shift);
    y.head(shift) = x.tail(shift);
    out.set(name, std::move(y));
  }
  return out;
}

namespace {
// term_correlation_time_s on inputs already built (a chance level reads many terms of a flight).
double correlation_time_on(const TermSpec& t, const TermInputs& in) {
  const ExprTerm* e = t.expr();
  if (!e) return std::numeric_limits<double>::quiet_NaN();
  const Eigen::MatrixXd signal = e->signal_values(in);
  return correlation_time_s(signal.col(0), in.dt_s);
}
}  // namespace

double term_correlation_time_s(const TermSpec& t, const Model& model, const FlightData& data) {
  if (!t.expr()) return std::numeric_limits<double>::quiet_NaN();
  return correlation_time_on(t, make_term_inputs(data, model.vector, model.bt_scale_nT));
}

ChanceLevel chance_level(const Model& model, const std::vector<const FlightData*>& flights,
                         const std::string& truth, const DiagnoseOptions& options,
                         double slowest_s) {
  ChanceLevel out;
  DiagnoseOptions quiet = options;
  // The single terms of the aircraft's states are what a round compares with: no joint set, no
  // flexible model of every channel, no motion or position channel (read as recorded, they
  // would rank as they do in the round itself).
  quiet.joint_selection = false;
  quiet.explainable_share = false;
  quiet.full_search = false;
  for (const double fraction : kChanceShifts) {
    for (const FlightData* f : flights) {
      const FlightData shifted = with_states_shifted(*f, model, truth, fraction);
      Diagnosis d;
      try {
        d = diagnose(model, shifted, truth, quiet);
      } catch (const Error&) {
        continue;  // a shifted flight the search cannot read gives no chance level
      }
      std::optional<TermInputs> inputs;  // built once per shifted flight, when a pace is read
      for (const Candidate& c : d.candidates) {
        if (!c.accepted || !reads_shiftable_channels_only(c.term, model, truth)) continue;
        if (c.explained_fraction <= std::min(out.share, out.slower_share)) continue;
        double pace_s = 0;
        if (std::isfinite(slowest_s)) {
          if (!inputs) inputs = make_term_inputs(shifted, model.vector, model.bt_scale_nT);
          pace_s = correlation_time_on(c.term, *inputs);
          if (!(pace_s <= slowest_s)) {  // slower (or of no signal): another pace's chance
            if (c.explained_fraction > out.slower_share) {
              out.slower_share = c.explained_fraction;
              out.slower_term = c.term.text();
            }
            continue;
          }
        }
        if (c.explained_fraction <= out.share) continue;
        out.share = c.explained_fraction;
        out.term = c.term.text();
        out.fraction = fraction;
        out.correlation_s = pace_s;
      }
    }
  }
  return out;
}

bool Round::drop_chance_slow_term(const DiagnoseOptions& options, std::set<std::string>* audited) {
  if (c_.flights.size() != 1 || c_.validation) return false;
  const LoopRound now = r_->rounds.back();
  const Model& model = r_->model;
  for (const TermSpec& t : model.terms) {
    if (!removable(c_.start, t) || fields_of(t).empty() || !low_pass_beyond(t, kSlowOnLinesMin_s) ||
        audited->count(t.text()))
      continue;
    audited->insert(t.text());
    const Model without = without_term(model, t);
    if (!reads_shiftable_channels_only(t, without, c_.truth)) continue;
    std::pair<Model, LoopRound> w;
    try {
      w = fit_score(without);
    } catch (const Error&) {
      continue;  // the model without it does not fit: the term stays
    }
    const LoopRound& lw = w.second;
    // Not where the model without it does worse than the model the loop started from: the
    // rest of the model was fitted around it (TL written as the exact norm, sized against the
    // reference with the drift in the residual), and taking it out alone would leave that.
    if (!(lw.heldout_std_nT <= (1 + 1e-9) * r_->rounds.front().heldout_std_nT)) continue;
    // Its share with every other term in place: the smaller of the two halves'.
    const double share = std::min(variance_share(now.selection_std_nT, lw.selection_std_nT),
                                  variance_share(now.confirmation_std_nT, lw.confirmation_std_nT));
    if (!std::isfinite(share)) continue;
    // Compared with chance terms of its own pace or faster: its signal's correlation time.
    const double pace_s = term_correlation_time_s(t, model, *c_.flights.front());
    const ChanceLevel chance =
        chance_level(w.first, c_.flights, c_.truth, options, std::isfinite(pace_s) ? pace_s : kInf);
    if (beyond_chance(share, chance) ||
        beyond_chance_to_the_resolution(now.heldout_std_nT, lw.heldout_std_nT, chance,
                                        options.resolution_nT))
      continue;
    char found[600];
    if (chance.term.empty())
      std::snprintf(found, sizeof(found),
                    "the search accepts no term of the recorded states read shifted in time "
                    "with a correlation time of at most its own %.0f s, and it must explain more "
                    "than nothing",
                    pace_s);
    else
      std::snprintf(found, sizeof(found),
                    "the search finds %.1f%% among the recorded states read shifted in time (%s "
                    "shifted by %.0f%% of the flight; correlation time %.0f s, its own %.0f s), "
                    "and it must leave at most what two such draws in turn leave",
                    100 * chance.share, chance.term.c_str(), 100 * chance.fraction,
                    chance.correlation_s, pace_s);
    char why[1000];
    std::snprintf(why, sizeof(why),
                  "a drift one flight cannot tell from chance: with every other term in place it "
                  "explains %.1f%% of the held-out variance (the smaller half's), where %s: "
                  "without it the held-out error %.4f -> %.4f nT; a second flight (--data "
                  "A.h5,B.h5 or --validate) tells whether %s carries it",
                  100 * share, found, now.heldout_std_nT, lw.heldout_std_nT, t.text().c_str());
    LoopRound& last = r_->rounds.back();
    last.removed.emplace_back(t.text(), why);
    take_scores(lw, &last);
    r_->model = std::move(w.first);
    return true;
  }
  return false;
}

}  // namespace magcomp::loop_steps
