// magcomp: diagnose's product screen: every pair of channels scored cheaply for a product
// term, the best fitted in full (see search.h).
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

// Every pair of channels screened cheaply for a product term field:x*y: on the held-out rows,
// the share of the base residual (each line's mean removed) that the product's three columns
// B̂i·x·y explain by least squares (no refit of the base). The screen only chooses which pairs
// are fitted: the best `keep` pairs not already in `taken` become jobs, scored like every other
// (fitted with the base, then accepted only if they lower the error on each fold by itself). It
// reads both folds because a product of a current that one kind of flying switches on can lie
// mostly in one of them. The earth-frame velocities are passed over (is_earth_frame_velocity).
// Two threads split the first channel.
std::vector<Job> screened_products(const Search& search, const std::vector<std::string>& sources,
                                   const std::vector<Job>& taken, size_t keep, int threads) {
  const std::vector<Eigen::Index>& rows = search.held;
  const auto m = static_cast<Eigen::Index>(rows.size());
  if (m < 100 || sources.size() < 2) return {};
  // The residual, each line's mean removed; the direction products B̂iB̂j and e·B̂i per row.
  Eigen::VectorXd e(m);
  for (Eigen::Index r = 0; r < m; ++r) e[r] = search.e0[rows[static_cast<size_t>(r)]];
  for (Eigen::Index start = 0, r = 1; r <= m; ++r) {
    if (r < m &&
        search.line[rows[static_cast<size_t>(r)]] == search.line[rows[static_cast<size_t>(start)]])
      continue;
    e.segment(start, r - start).array() -= e.segment(start, r - start).mean();
    start = r;
  }
  const double ee = e.squaredNorm();
  if (!(ee > 0)) return {};
  Eigen::Matrix<double, Eigen::Dynamic, 9> w(m, 9);  // xx xy xz yy yz zz, e·x e·y e·z
  for (Eigen::Index r = 0; r < m; ++r) {
    const Eigen::Vector3d d = search.inputs.direction.row(rows[static_cast<size_t>(r)]);
    w.row(r) << d.x() * d.x(), d.x() * d.y(), d.x() * d.z(), d.y() * d.y(), d.y() * d.z(),
        d.z() * d.z(), e[r] * d.x(), e[r] * d.y(), e[r] * d.z();
  }
  // The channels on those rows, standardised (a product's share does not depend on scale).
  Eigen::MatrixXd x(m, static_cast<Eigen::Index>(sources.size()));
  for (size_t c = 0; c < sources.size(); ++c) {
    const FlightData::Column v = search.data.column(sources[c]);
    auto col = x.col(static_cast<Eigen::Index>(c));
    for (Eigen::Index r = 0; r < m; ++r) col[r] = v[rows[static_cast<size_t>(r)]];
    // A channel with gaps, or an earth-frame velocity: not screened.
    if (!col.allFinite() || is_earth_frame_velocity(sources[c])) col.setZero();
    const double sd = std::sqrt((col.array() - col.mean()).square().mean());
    if (sd > 0) col /= sd;
  }
  std::set<std::string> already;
  for (const Job& j : taken) already.insert(j.term.text());
  const auto n = static_cast<Eigen::Index>(sources.size());
  auto screen = [&](int part) {
    std::vector<std::pair<double, std::pair<Eigen::Index, Eigen::Index>>> out;
    for (Eigen::Index a = part; a < n; a += std::max(threads, 1)) {
      for (Eigen::Index b = a + 1; b < n; ++b) {
        Eigen::Matrix<double, 9, 1> acc = Eigen::Matrix<double, 9, 1>::Zero();
        for (Eigen::Index r = 0; r < m; ++r) {
          const double z = x(r, a) * x(r, b), z2 = z * z;
          acc.head<6>() += z2 * w.row(r).head<6>().transpose();
          acc.tail<3>() += z * w.row(r).tail<3>().transpose();
        }
        Eigen::Matrix3d g;
        g << acc[0], acc[1], acc[2], acc[1], acc[3], acc[4], acc[2], acc[4], acc[5];
        g.diagonal().array() += 1e-9 * std::max(g.trace(), 1e-300);
        const Eigen::Vector3d h = acc.tail<3>();
        const double explained = h.dot(g.ldlt().solve(h)) / ee;
        if (std::isfinite(explained)) out.push_back({explained, {a, b}});
      }
    }
    return out;
  };
  std::vector<std::future<decltype(screen(0))>> parts;
  for (int t = 0; t < std::max(threads, 1); ++t)
    parts.push_back(std::async(std::launch::async, screen, t));
  std::vector<std::pair<double, std::pair<Eigen::Index, Eigen::Index>>> all;
  for (auto& p : parts) {
    auto v = p.get();
    all.insert(all.end(), v.begin(), v.end());
  }
  std::sort(all.begin(), all.end(), [](const auto& p, const auto& q) { return p.first > q.first; });
  std::vector<Job> jobs;
  for (const auto& [explained, pair] : all) {
    if (jobs.size() >= keep) break;
    const std::string& xa = sources[static_cast<size_t>(pair.first)];
    const std::string& xb = sources[static_cast<size_t>(pair.second)];
    const std::string spec = "field:" + xa + "*" + xb;
    if (already.count(spec)) continue;
    jobs.push_back({TermSpec(spec), "product of two channels", xa + "*" + xb});
  }
  return jobs;
}

}  // namespace magcomp::diagnose_search
