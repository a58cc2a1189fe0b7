// magcomp: a round of diagnose_loop looking one round ahead before it keeps its first term
// (loop_round.h, Round::looking_ahead).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "loop_round.h"
#include "magcomp/core/error.h"

namespace magcomp::loop_steps {

namespace {

// One way the round may go: its term fitted alone, and the best next term (by held-out error) of
// those the model with it, diagnosed again, lets pass (scored with both; the term alone when
// none passes).
struct Path {
  size_t index = 0;  // in the round's eligible candidates
  std::pair<Model, LoopRound> alone;
  LoopRound two;
  std::string next;  // the next term ("" when none passes)
};

}  // namespace

std::vector<Eligible> Round::looking_ahead(const std::vector<Eligible>& eligible,
                                           const DiagnoseOptions& options) {
  if (!c_.options.look_ahead) return eligible;
  const LoopRound& now = r_->rounds.back();
  // The first two single tries that pass alone: the term first_single would keep, and the
  // runner-up of other channels.
  std::vector<Path> paths;
  for (size_t k : single_tries(eligible)) {
    try {
      Model m = r_->model;
      add_candidate_term(eligible[k].term, eligible[k].slow, c_.truth, &m);
      auto fitted = fit_score(std::move(m));
      if (!refusal(fitted.second, now, c_.options).empty()) continue;
      Path p;
      p.index = k;
      p.alone = std::move(fitted);
      paths.push_back(std::move(p));
    } catch (const Error&) {
    }
    if (paths.size() == 2) break;
  }
  if (paths.size() < 2) return eligible;
  const double first_nT = paths[0].alone.second.heldout_std_nT;
  const double runner_up_nT = paths[1].alone.second.heldout_std_nT;
  if (!(runner_up_nT <= kLookAheadRatio * first_nT)) return eligible;
  // Each one round ahead: the model with it diagnosed again, and the best of that diagnosis's
  // single tries that pass beside it (a first try may be a term's own parameter estimated
  // again, which the round after would write anyway). The next term must read none of the
  // path's term's channels: the look-ahead asks whether a term stands in for effects that other
  // terms write, and a second term of its own channel writes that channel's shape, not another
  // effect.
  for (Path& p : paths) {
    const std::set<std::string> own = fields_of(eligible[p.index].term);
    p.two = p.alone.second;
    std::vector<Diagnosis> dxs;
    for (const FlightData* f : c_.flights)
      dxs.push_back(diagnose(p.alone.first, *f, c_.truth, options));
    const std::vector<Eligible> next =
        eligible_candidates(dxs, c_.min_share, !c_.options.refuse_within_span_terms);
    for (size_t j : single_tries(next)) {
      const std::set<std::string> reads = fields_of(next[j].term);
      if (std::any_of(reads.begin(), reads.end(),
                      [&](const std::string& x) { return own.count(x) > 0; }))
        continue;
      try {
        Model m = p.alone.first;
        add_candidate_term(next[j].term, next[j].slow, c_.truth, &m);
        const LoopRound lr = fit_score(std::move(m)).second;
        if (!refusal(lr, p.alone.second, c_.options).empty()) continue;
        if (!p.next.empty() && !(lr.heldout_std_nT < p.two.heldout_std_nT)) continue;
        p.two = lr;
        p.next = next[j].term.text();
      } catch (const Error&) {
      }
    }
  }
  if (!improves_on(paths[1].two, paths[0].two)) return eligible;
  const Eligible& first = eligible[paths[0].index];
  const Eligible& runner_up = eligible[paths[1].index];
  // "X then Y leaves a nT held out (X alone b)", or "X leaves b nT held out and no term passes
  // after it".
  const auto two_rounds = [](const Path& p, const Eligible& e) {
    const auto nT = [](double v) {
      char buf[32];
      std::snprintf(buf, sizeof(buf), "%.4f", v);
      return std::string(buf);
    };
    const std::string x = e.term.text();
    if (p.next.empty())
      return x + " leaves " + nT(p.two.heldout_std_nT) + " nT held out and no term passes after it";
    return x + " then " + p.next + " leaves " + nT(p.two.heldout_std_nT) + " nT held out (" + x +
           " alone " + nT(p.alone.second.heldout_std_nT) + ")";
  };
  const std::string why = "looked at one round ahead, " + two_rounds(paths[0], first) + ", where " +
                          two_rounds(paths[1], runner_up) +
                          ": it stands in for effects that other terms write";
  rejected_.emplace_back(first.term.text(), why);
  std::vector<Eligible> out{runner_up};
  for (size_t k = 0; k < eligible.size(); ++k)
    if (k != paths[0].index && k != paths[1].index) out.push_back(eligible[k]);
  return out;
}

}  // namespace magcomp::loop_steps
