// magcomp: diagnose's joint selection: a set of candidate terms chosen together, every subset of
// a pool fitted with the model's columns and scored on the held-out lines, its choice repeated on
// bootstrap resamplings of those lines (JointSet in diagnose.h).
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>

#include "magcomp/core/diagnose/residual_floor.h"
#include "magcomp/core/error.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {
namespace {

// A term of the pool: its columns over the flight (NaN read as 0) on the held-out rows, and as
// the fit reads them.
struct PoolTerm {
  TermSpec term;
  std::string channel;
  Eigen::MatrixXd held;  // n_held x k
  Eigen::MatrixXd band;  // fit rows x k
};

// The held-out rows in groups: each line within one half (its mean is removed within the half,
// as fold_std does). Sums per group make a resampling of the lines a reweighting of groups.
class Groups {
 public:
  explicit Groups(const Search& s) {
    std::map<std::pair<int, double>, int> id;
    for (Eigen::Index i : s.held) {
      const int fold = s.fold[static_cast<size_t>(i)];
      const auto key = std::make_pair(fold, s.line[i]);
      auto it = id.find(key);
      if (it == id.end()) {
        it = id.emplace(key, static_cast<int>(fold_of_.size())).first;
        fold_of_.push_back(fold);
      }
      group_.push_back(it->second);
    }
  }
  int size() const { return static_cast<int>(fold_of_.size()); }
  int fold_of(int g) const { return fold_of_[static_cast<size_t>(g)]; }

  // Each group's sum of squares about its mean and its count, for an error on the held rows.
  std::pair<Eigen::VectorXd, Eigen::VectorXd> stats(const Eigen::VectorXd& e) const {
    Eigen::VectorXd n = Eigen::VectorXd::Zero(size()), s = n, ss = n;
    for (Eigen::Index r = 0; r < e.size(); ++r) {
      if (!std::isfinite(e[r])) continue;
      const int g = group_[static_cast<size_t>(r)];
      n[g] += 1;
      s[g] += e[r];
      ss[g] += e[r] * e[r];
    }
    Eigen::VectorXd centred = Eigen::VectorXd::Zero(size());
    for (int g = 0; g < size(); ++g)
      if (n[g] > 0) centred[g] = ss[g] - s[g] * s[g] / n[g];
    return {centred, n};
  }

  // The error std over the groups of one half (-1: both), each group weighted by `w`, nT.
  double std_of(const std::pair<Eigen::VectorXd, Eigen::VectorXd>& st, const Eigen::VectorXd& w,
                int which) const {
    double ss = 0, n = 0;
    for (int g = 0; g < size(); ++g) {
      if (which >= 0 && fold_of(g) != which) continue;
      ss += w[g] * st.first[g];
      n += w[g] * st.second[g];
    }
    return n > 1 ? std::sqrt(ss / n) : NAN;
  }

 private:
  std::vector<int> group_;  // per held row
  std::vector<int> fold_of_;
};

double variance_gain(double with_nT, double without_nT) {
  return 1.0 - std::pow(with_nT / without_nT, 2.0);
}

// The pool: the ranked candidates fitted by the band-pass (not the lag, not a slow term, not a
// re-estimate of a model term's shape, no grown chain: kJointMaxComplexity), at most two per
// channel, kJointPool in rank order; then
// the plain term of each of the three channels the remaining residual follows most (effects
// that cancel one another show in the residual's channels, not in each term's own share).
std::set<std::string> model_shapes(const Search& search) {
  std::set<std::string> out;
  for (const TermSpec& t : search.model.terms)
    if (const ExprTerm* e = t.expr()) out.insert(e->shape());
  return out;
}

// Whether a candidate may join the pool (see pool_of).
bool poolable(const Candidate& c, const std::set<std::string>& model_shapes) {
  return !c.slow && !c.term.empty() && c.term.expr() && !c.channel.empty() &&
         std::isfinite(c.std_after_nT) && !c.term.expr()->signal().has_free() &&
         term_complexity(c.term) <= kJointMaxComplexity &&
         !model_shapes.count(c.term.expr()->shape());
}

std::vector<PoolTerm> pool_of(const Search& search, const std::vector<Candidate>& candidates,
                              const ExplainableShare& ex) {
  const std::set<std::string> shapes = model_shapes(search);
  std::vector<std::pair<TermSpec, std::string>> chosen;
  std::set<std::string> texts;
  std::map<std::string, int> per_channel;
  for (const Candidate& c : candidates) {
    if (chosen.size() >= kJointPool) break;
    if (!poolable(c, shapes) || per_channel[c.channel] >= 2) continue;
    ++per_channel[c.channel];
    texts.insert(c.term.text());
    chosen.emplace_back(c.term, c.channel);
  }
  constexpr size_t kResidualChannels = 3;
  for (size_t k = 0; !ex.within_noise && k < ex.channels.size() && k < kResidualChannels; ++k) {
    const std::string& ch = ex.channels[k].first;
    if (is_position_channel(ch) || ch == search.model.scalar || !search.data.has(ch)) continue;
    try {
      TermSpec plain(plain_spec(ch));
      if (shapes.count(plain.expr() ? plain.expr()->shape() : plain.text()) ||
          !texts.insert(plain.text()).second)
        continue;
      chosen.emplace_back(std::move(plain), ch);
    } catch (const Error&) {
    }
  }
  std::vector<PoolTerm> pool;
  const auto held_rows = static_cast<Eigen::Index>(search.held.size());
  for (auto& [term, channel] : chosen) {
    const Eigen::MatrixXd cols = search.columns_of(term.term()).unaryExpr([](double v) {
      return std::isfinite(v) ? v : 0.0;
    });
    if (cols.cols() == 0) continue;
    PoolTerm p{term, channel, Eigen::MatrixXd(held_rows, cols.cols()), search.band(cols)};
    if (!(p.band.squaredNorm() > 0) || !p.band.allFinite()) continue;
    for (Eigen::Index r = 0; r < held_rows; ++r)
      p.held.row(r) = cols.row(search.held[static_cast<size_t>(r)]);
    pool.push_back(std::move(p));
  }
  return pool;
}

}  // namespace

JointSet joint_selection(const Search& search, const std::vector<Candidate>& candidates,
                         const ExplainableShare& explainable, const DiagnoseOptions& options) {
  JointSet out;
  // Nothing to answer: no candidate accepted alone, or a lead the pool cannot hold.
  if (candidates.empty() || !candidates.front().accepted ||
      !poolable(candidates.front(), model_shapes(search)))
    return out;
  const std::vector<PoolTerm> pool = pool_of(search, candidates, explainable);
  out.pool_size = static_cast<int>(pool.size());
  if (pool.size() < 2) return out;
  const Groups groups(search);
  const auto held_rows = static_cast<Eigen::Index>(search.held.size());
  // The base error on the held rows without the base's band-pass correction, and its columns.
  Eigen::VectorXd y(held_rows);
  Eigen::MatrixXd a0(held_rows, search.a0.cols());
  for (Eigen::Index r = 0; r < held_rows; ++r) {
    const Eigen::Index i = search.held[static_cast<size_t>(r)];
    y[r] = search.scalar[i] - search.truth[i] - search.slow0[i];
    a0.row(r) = search.a0.row(i);
  }
  // Every subset of up to kJointMaxTerms terms (subset 0: none), fitted and scored.
  // A set holds one term per channel: each effect by a term of its own channel.
  std::vector<std::vector<int>> subsets = {{}};
  const int k = static_cast<int>(pool.size());
  const auto apart = [&](int a, int b) {
    return pool[static_cast<size_t>(a)].channel != pool[static_cast<size_t>(b)].channel;
  };
  for (int a = 0; a < k; ++a) {
    subsets.push_back({a});
    for (int b = a + 1; b < k; ++b) {
      if (!apart(a, b)) continue;
      subsets.push_back({a, b});
      for (int c = b + 1; kJointMaxTerms >= 3 && c < k; ++c)
        if (apart(a, c) && apart(b, c)) subsets.push_back({a, b, c});
    }
  }
  std::map<std::vector<int>, size_t> index;
  for (size_t s = 0; s < subsets.size(); ++s) index[subsets[s]] = s;
  std::vector<std::pair<Eigen::VectorXd, Eigen::VectorXd>> stats(subsets.size());
  for (size_t s = 0; s < subsets.size(); ++s) {
    Eigen::Index width = 0;
    for (int t : subsets[s]) width += pool[static_cast<size_t>(t)].band.cols();
    Eigen::MatrixXd band(search.yf.size(), width), held(held_rows, width);
    Eigen::Index col = 0;
    for (int t : subsets[s]) {
      const PoolTerm& p = pool[static_cast<size_t>(t)];
      band.middleCols(col, p.band.cols()) = p.band;
      held.middleCols(col, p.held.cols()) = p.held;
      col += p.band.cols();
    }
    const Eigen::VectorXd coef = search.profile->solve(band, nullptr);
    Eigen::VectorXd e = Eigen::VectorXd::Constant(held_rows, NAN);
    if (coef.allFinite()) e = y - a0 * coef.head(a0.cols()) - held * coef.tail(width);
    stats[s] = groups.stats(e);
  }
  const double accept = options.accept_fraction, resolution = options.resolution_nT;
  // The term the one-at-a-time search takes first: the first ranked candidate, when accepted.
  // When it is not in the pool (a slow term, the lag), the round is left to that search.
  // Without one (no candidate passes alone), pairs that act together are the loop's pair step's
  // (diagnose_loop), tried among the residual's own channels: a set chosen among every rejected
  // candidate would fit the held-out lines it is chosen on.
  size_t lead = 0;  // its subset
  if (candidates.empty() || !candidates.front().accepted) return out;
  for (size_t t = 0; t < pool.size() && lead == 0; ++t)
    if (pool[t].term == candidates.front().term) lead = index.at({static_cast<int>(t)});
  if (lead == 0) return out;
  // The set chosen with group weights `w` (0: none), and every subset's scores.
  const auto choose = [&](const Eigen::VectorXd& w) {
    std::vector<double> sel(subsets.size()), conf(subsets.size()), held(subsets.size());
    for (size_t s = 0; s < subsets.size(); ++s) {
      sel[s] = groups.std_of(stats[s], w, 0);
      conf[s] = groups.std_of(stats[s], w, 1);
      held[s] = groups.std_of(stats[s], w, -1);
    }
    const auto on = [&](double with, double without) {
      return variance_gain(with, without) >= accept && without - with >= resolution;
    };
    // `s` lowers each half's error against subset `than` by the accepted share of the variance
    // and the resolution.
    const auto beats = [&](size_t s, size_t than) {
      return on(sel[s], sel[than]) && on(conf[s], conf[than]);
    };
    const int lead_term = subsets[lead].front();
    std::vector<size_t> admissible;
    for (size_t s = 1; s < subsets.size(); ++s) {
      const std::vector<int>& set = subsets[s];
      if (set.size() < 2 || !on(sel[s], sel[0]) || !on(conf[s], conf[0])) continue;
      // In place of the lead (a look-alike the one-at-a-time search would take first), and
      // better than it: a set holding the lead is that search's own path.
      if (std::find(set.begin(), set.end(), lead_term) != set.end() || !beats(s, lead)) continue;
      bool needed = true;
      for (size_t drop = 0; needed && drop < set.size(); ++drop) {
        std::vector<int> rest = set;
        rest.erase(rest.begin() + static_cast<long>(drop));
        needed = beats(s, index.at(rest));
      }
      if (needed) admissible.push_back(s);
    }
    // The lowest held-out error; among the sets within the accepted share of it, the fewest
    // terms, then the simplest.
    size_t best = 0;
    for (size_t s : admissible)
      if (best == 0 || held[s] < held[best]) best = s;
    const auto complexity = [&](size_t s) {
      int c = 0;
      for (int t : subsets[s]) c += term_complexity(pool[static_cast<size_t>(t)].term);
      return std::make_pair(subsets[s].size(), c);
    };
    const size_t lowest = best;
    for (size_t s : admissible)
      if (variance_gain(held[lowest], held[s]) < accept && complexity(s) < complexity(best))
        best = s;
    return std::make_tuple(best, std::move(held), std::move(sel), std::move(conf));
  };
  const Eigen::VectorXd ones = Eigen::VectorXd::Ones(groups.size());
  const auto [best, held, sel, conf] = choose(ones);
  if (best == 0) return out;
  // Stability: the same choice on bootstrap resamplings of each half's lines.
  std::vector<std::vector<int>> by_fold(2);
  for (int g = 0; g < groups.size(); ++g)
    if (groups.fold_of(g) == 0 || groups.fold_of(g) == 1)
      by_fold[static_cast<size_t>(groups.fold_of(g))].push_back(g);
  std::mt19937 rng(20240917u);
  int same = 0;
  for (int b = 0; b < kJointResamples; ++b) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(groups.size());
    for (const auto& gs : by_fold) {
      if (gs.empty()) continue;
      std::uniform_int_distribution<size_t> pick(0, gs.size() - 1);
      for (size_t d = 0; d < gs.size(); ++d) w[gs[pick(rng)]] += 1.0;
    }
    if (std::get<0>(choose(w)) == best) ++same;
  }
  out.stability = static_cast<double>(same) / kJointResamples;
  if (out.stability < kJointStability) return out;
  for (int t : subsets[best]) {
    out.terms.push_back(pool[static_cast<size_t>(t)].term);
    out.alone_std_nT.push_back(held[index.at({t})]);
  }
  out.selection_std_nT = sel[best];
  out.confirmation_std_nT = conf[best];
  out.heldout_std_nT = held[best];
  out.best_single = pool[static_cast<size_t>(subsets[lead].front())].term.text();
  out.best_single_std_nT = held[lead];
  return out;
}

}  // namespace magcomp::diagnose_search
