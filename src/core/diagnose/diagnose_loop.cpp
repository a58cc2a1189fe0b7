// magcomp: the diagnose -> add -> refit loop.
#include "magcomp/core/diagnose/diagnose_loop.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

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

// Scores of a model: held-out lines, all lines, FOM, validation flight.
LoopRound score(const Model& model, const FlightData& data, const std::string& truth,
                const std::vector<double>& held, const FlightData* validation) {
  LoopRound r;
  const Evaluation ev = evaluate_model(model, data, truth, false);
  r.heldout_std_nT = std_on_lines(ev, held);
  r.all_std_nT = ev.std_nT;
  r.fom_nT = ev.fom.signatures.empty() ? NAN : ev.fom.fom_nT;
  if (validation) r.validation_std_nT = evaluate_model(model, *validation, truth, false).std_nT;
  return r;
}

// Why a scored candidate model is refused against the current one ("" when it is kept).
std::string refusal(const LoopRound& next, const LoopRound& now) {
  char buf[256];
  if (!(next.heldout_std_nT < now.heldout_std_nT)) {
    std::snprintf(buf, sizeof(buf), "the held-out error would not fall (%.3f -> %.3f nT)",
                  now.heldout_std_nT, next.heldout_std_nT);
    return buf;
  }
  if (std::isfinite(now.validation_std_nT) && !(next.validation_std_nT < now.validation_std_nT)) {
    std::snprintf(buf, sizeof(buf),
                  "the error on the validation flight would not fall (%.3f -> %.3f nT)",
                  now.validation_std_nT, next.validation_std_nT);
    return buf;
  }
  return "";
}

}  // namespace

LoopResult diagnose_loop(const Model& start, const FlightData& data, const std::string& truth,
                         int max_rounds, double min_share, const DiagnoseOptions& options,
                         const std::function<void(int, const Diagnosis&)>& on_round,
                         const FlightData* validation) {
  constexpr size_t kTriesPerRound = 3;
  LoopResult r;
  r.model = start;
  if (!r.model.fitted()) fit_model(r.model, {&data});
  std::vector<double> held;
  for (int round = 1;; ++round) {
    Diagnosis dx = diagnose(r.model, data, truth, options);
    if (round == 1) {
      held = dx.selection_lines;
      held.insert(held.end(), dx.confirmation_lines.begin(), dx.confirmation_lines.end());
      r.rounds.push_back(score(r.model, data, truth, held, validation));
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
    // The accepted candidates in rank order: the first that passes every check is kept.
    std::vector<std::pair<std::string, std::string>> rejected;
    bool kept = false;
    for (size_t k = 0; k < dx.candidates.size() && k < kTriesPerRound; ++k) {
      const Candidate& c = dx.candidates[k];
      if (!c.accepted || c.explained_fraction < min_share) break;
      Model next = r.model;
      next.add_term(c.term);
      next.coefficients.resize(0);
      fit_model(next, {&data});
      LoopRound lr = score(next, data, truth, held, validation);
      const std::string why = refusal(lr, r.rounds.back());
      if (!why.empty()) {
        rejected.emplace_back(c.term, why);
        continue;
      }
      lr.round = round;
      lr.added = c.term;
      lr.explained = c.explained_fraction;
      lr.rejected = std::move(rejected);
      r.rounds.push_back(std::move(lr));
      r.model = std::move(next);
      kept = true;
      break;
    }
    if (!kept) {
      r.stop_reason = "no accepted term passes: ";
      for (size_t k = 0; k < rejected.size(); ++k) {
        r.stop_reason += (k ? "; " : "") + rejected[k].first + ": " + rejected[k].second;
      }
      r.stop_reason += ": stopped";
      r.last = std::move(dx);
      break;
    }
  }
  return r;
}

}  // namespace magcomp
