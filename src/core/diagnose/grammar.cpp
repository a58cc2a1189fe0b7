// magcomp: diagnose's grammar growth: the best electrical terms grow by one transform
// (see search.h).
#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <future>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

// The grammar search: the best-scoring electrical channel terms so far grow by one transform each,
// a dynamic one after the chain (lp(?), d, sat(?)) or a static law before it (pow(2), abs), within
// a budget of kMaxChain transforms; the parameters estimated so far stay as numbers, so each child
// has at most one '?'. kRefineParents parents per level, two levels: best-first.
constexpr size_t kRefineParents = 4;
constexpr size_t kMaxChain = 3;

// True when a time constant of the term sits at the top of its scan: the flight cannot tell it
// from a slower one, so it stands for a drift, not an estimated response. Neither grown from nor
// kept as a grown chain.
bool at_slow_edge(const Term& term, const Search& search) {
  const auto* e = dynamic_cast<const ExprTerm*>(&term);
  if (!e) return false;
  const double top_s = longest_scanned_time_constant_s(search.dt, search.span);
  for (const auto& t : e->signal().transforms) {
    if (t.kind != TransformKind::LowPass && t.kind != TransformKind::HighPass) continue;
    if (at_longest_scanned_time_constant(t.param, top_s)) return true;
  }
  return false;
}

std::vector<Job> refined_jobs(const Model& model, const Search& search,
                              const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                              std::set<std::string>* seen,
                              const std::set<std::string>& rate_recorded) {
  std::vector<std::pair<double, size_t>> order;
  for (size_t k = 0; k < jobs.size(); ++k) {
    // Chains are the laws of the aircraft's loads and states (heating, saturation, switching):
    // grown from terms of its state channels only (currents, voltages, temperatures, positions
    // of its surfaces, ...; and their products). An attitude or velocity grown into |x| through
    // a slow low-pass becomes a proxy of when the aircraft turned.
    if (!scored[k].ok || jobs[k].channel.empty() || jobs[k].channel == model.scalar ||
        !is_aircraft_state(jobs[k].channel.substr(0, jobs[k].channel.find('*'))))
      continue;
    // Grown from the terms that explain most on both folds (the smaller share), so a term
    // that only fits the selection lines does not take the budget.
    order.emplace_back(-std::min(share(scored[k].sel, search.base_std[0]),
                                 share(scored[k].conf, search.base_std[1])),
                       k);
  }
  std::sort(order.begin(), order.end());
  std::set<std::string> shapes;  // a model term's shape is re-estimated, not grown
  for (const TermSpec& t : model.terms)
    if (const ExprTerm* e = t.expr()) shapes.insert(e->shape());
  std::vector<Job> out;
  size_t parents = 0;
  for (const auto& entry : order) {
    const size_t k = entry.second;  // a plain variable: lambdas may not capture a binding (C++17)
    if (parents >= kRefineParents) break;
    const auto* e = dynamic_cast<const ExprTerm*>(scored[k].term.get());
    if (!e || e->signal().has_free() || e->signal().transforms.size() >= kMaxChain ||
        at_slow_edge(*e, search))
      continue;
    ++parents;
    const SignalExpr& sig = e->signal();
    auto child = [&](const Transform& t, bool front) {
      for (const auto& have : sig.transforms)
        if (have.kind == t.kind) return;  // one of each kind in a chain
      SignalExpr c = sig;
      if (front) {
        c.transforms.insert(c.transforms.begin(), t);
      } else {
        c.transforms.push_back(t);
      }
      auto term = std::make_shared<const ExprTerm>(e->projection(), c);
      if (shapes.count(term->shape()) || !seen->insert(term->spec()).second) return;
      out.push_back({TermSpec(std::move(term)), "chain (grammar search)", jobs[k].channel});
    };
    child({TransformKind::LowPass, 0.0, true}, false);
    // d commutes with low-passes and delays: such a chain of a source whose rate is recorded,
    // differentiated, is the recorded rate's chain.
    const bool rate_is_recorded =
        sig.sources.size() == 1 && rate_recorded.count(sig.sources[0]) &&
        std::all_of(sig.transforms.begin(), sig.transforms.end(), [](const Transform& t) {
          return t.kind == TransformKind::LowPass || t.kind == TransformKind::Delay;
        });
    if (!rate_is_recorded) child({TransformKind::Derivative, 0.0, false}, false);
    bool level_units = true;  // sat(?) is scanned over the source's range: not after d or int
    for (const auto& t : sig.transforms) {
      if (t.kind == TransformKind::Derivative || t.kind == TransformKind::Integral ||
          t.kind == TransformKind::Decay || t.kind == TransformKind::HighPass)
        level_units = false;
    }
    if (level_units) child({TransformKind::Saturate, 0.0, true}, false);
    // x² only where x varies by a good part of its level (elsewhere it is x rescaled, a way
    // around the ridge, not a new shape: 5 V ± noise squared); |x| only where x takes both
    // signs (elsewhere it is x itself).
    const SignalRange range = signal_range(sig, search.data);
    if (range.hi - range.lo >= 0.5 * std::max(std::abs(range.lo), std::abs(range.hi)))
      child({TransformKind::Power, 2.0, false}, true);
    if (range.lo < 0) child({TransformKind::Abs, 0.0, false}, true);
  }
  return out;
}

}  // namespace magcomp::diagnose_search
