// magcomp: the diagnose -> add -> refit loop.
#include "magcomp/core/diagnose/diagnose_loop.h"

#include <algorithm>
#include <cmath>

#include "magcomp/core/evaluate/evaluation.h"

namespace magcomp {
namespace {

// Pooled std of an evaluation's error over the given lines (all lines when empty), nT.
double std_on_lines(const Evaluation& ev, const std::vector<double>& lines) {
  if (lines.empty()) return ev.std_nT;
  double ss = 0, n = 0;
  for (const auto& l : ev.per_line) {
    if (std::find(lines.begin(), lines.end(), l.line) == lines.end()) continue;
    ss += l.std_nT * l.std_nT * static_cast<double>(l.n);
    n += static_cast<double>(l.n);
  }
  return n > 0 ? std::sqrt(ss / n) : ev.std_nT;
}

}  // namespace

LoopResult diagnose_loop(const Model& start, const FlightData& data, const std::string& truth,
                         int max_rounds, double min_share, const DiagnoseOptions& options,
                         const std::function<void(int, const Diagnosis&)>& on_round) {
  LoopResult r;
  r.model = start;
  if (!r.model.fitted()) fit_model(r.model, {&data});
  std::vector<double> held;
  for (int round = 1;; ++round) {
    Diagnosis dx = diagnose(r.model, data, truth, options);
    if (round == 1) {
      held = dx.selection_lines;
      held.insert(held.end(), dx.confirmation_lines.begin(), dx.confirmation_lines.end());
      LoopRound r0;
      const Evaluation ev = evaluate_model(r.model, data, truth);
      r0.heldout_std_nT = std_on_lines(ev, held);
      r0.all_std_nT = ev.std_nT;
      r0.fom_nT = ev.fom.signatures.empty() ? NAN : ev.fom.fom_nT;
      r.rounds.push_back(r0);
    }
    if (on_round) on_round(round, dx);
    const Candidate* top = dx.candidates.empty() ? nullptr : &dx.candidates.front();
    if (!top || !top->accepted || top->explained_fraction < min_share) {
      r.stop_reason = dx.verdict;
      r.last = std::move(dx);
      break;
    }
    if (round > max_rounds) {
      r.stop_reason = "stopped after " + std::to_string(max_rounds) + " rounds; " + dx.verdict;
      r.last = std::move(dx);
      break;
    }
    Model next = r.model;
    next.add_term(top->term);
    next.coefficients.resize(0);
    fit_model(next, {&data});
    LoopRound lr;
    lr.round = round;
    lr.added = top->term;
    lr.explained = top->explained_fraction;
    const Evaluation ev = evaluate_model(next, data, truth);
    lr.heldout_std_nT = std_on_lines(ev, held);
    lr.all_std_nT = ev.std_nT;
    lr.fom_nT = ev.fom.signatures.empty() ? NAN : ev.fom.fom_nT;
    if (!(lr.heldout_std_nT < r.rounds.back().heldout_std_nT)) {  // never worse on unseen lines
      r.stop_reason = "adding " + top->term + " would not lower the held-out error (" +
                      std::to_string(lr.heldout_std_nT) + " nT): stopped";
      r.last = std::move(dx);
      break;
    }
    r.rounds.push_back(lr);
    r.model = std::move(next);
  }
  return r;
}

}  // namespace magcomp
