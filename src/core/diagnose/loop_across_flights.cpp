// magcomp: a term each flight's held-out halves cannot confirm, judged with the flights as the
// halves (loop_round.h: across_flights).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "loop_round.h"
#include "magcomp/core/error.h"

namespace magcomp::loop_steps {

bool across_flights(const LoopContext& c, int round, const std::vector<double>& lines,
                    LoopResult* r, std::vector<HeldOut>* held_out) {
  if (c.flights.size() < 2 || held_out->size() != c.flights.size()) return false;
  // Each flight's term it names but cannot confirm, once.
  std::vector<Eligible> tries;
  for (const FlightData* f : c.flights) {
    const Diagnosis dx = diagnose(r->model, *f, c.truth, c.options);
    const std::string& t = dx.one_half.term;
    if (t.empty() || std::any_of(tries.begin(), tries.end(),
                                 [&](const Eligible& e) { return e.term.text() == t; }))
      continue;
    for (const Candidate& cand : dx.candidates) {
      if (cand.term.text() != t) continue;
      if (cand.slow && lines.empty() && r->model.fit.slow_lines.empty()) break;
      tries.push_back({cand.term, cand.slow, dx.one_half.explained, cand.base_span_share});
      break;
    }
  }
  if (tries.empty()) return false;
  // The flights as the halves.
  std::vector<HeldOut> by_flight = *held_out;
  for (size_t f = 0; f < by_flight.size(); ++f)
    for (signed char& h : by_flight[f].fold)
      if (h >= 0) h = static_cast<signed char>(f % 2);
  LoopResult trial = *r;
  const bool slow =
      std::any_of(tries.begin(), tries.end(), [](const Eligible& e) { return e.slow; });
  if (slow && trial.model.fit.slow_lines.empty()) trial.model.fit.slow_lines = lines;
  const LoopContext flights_as_halves{c.start,      c.flights, c.truth,    by_flight,
                                      c.validation, c.options, c.min_share};
  // The last round rescored so for the step's checks, its own scores given back after.
  const size_t previous = trial.rounds.size() - 1;
  const LoopRound as_scored = trial.rounds[previous];
  try {
    take_scores(score(trial.model, c.flights, c.truth, by_flight, c.validation),
                &trial.rounds[previous]);
  } catch (const Error&) {
    return false;  // the model does not fit with its slow terms sized on the lines
  }
  const LoopRound rescored = trial.rounds[previous];
  Round step(flights_as_halves, round, &trial);
  if (!step.first_single(tries)) return false;
  if (c.options.joint_steps) step.backward_pass();
  LoopRound& kept = trial.rounds.back();
  kept.flight_halves = true;
  kept.flight_halves_before_nT[0] = rescored.heldout_std_nT;
  kept.flight_halves_before_nT[1] = rescored.selection_std_nT;
  kept.flight_halves_before_nT[2] = rescored.confirmation_std_nT;
  kept.explained = variance_share(kept.heldout_std_nT, rescored.heldout_std_nT);
  trial.rounds[previous] = as_scored;
  *r = std::move(trial);
  *held_out = std::move(by_flight);
  return true;
}

}  // namespace magcomp::loop_steps
