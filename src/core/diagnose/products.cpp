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

#include "line_means.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

// Every pair of channels screened cheaply for a product term field:x*y: on the held-out rows,
// the share of the base residual (each line's mean removed) that the product's three columns
// B̂i·x·y (each line's mean removed too) explain by least squares beside the base's own columns (a
// partial regression: the part of the product the base already spans -- a rate times a steady
// current is mostly an eddy column -- explains nothing the refit would keep). The screen only
// chooses which pairs are fitted: the best `keep` pairs not already in `taken` become jobs, scored
// like every other (fitted with the base, then accepted only if they lower the error on each fold
// by itself). It reads both folds because a product of a current that one kind of flying switches
// on can lie mostly in one of them. The earth-frame velocities are passed over
// (is_earth_frame_velocity). Each first channel's pairs are matrix products; two threads split the
// first channel.
std::vector<Job> screened_products(const Search& search, const std::vector<std::string>& sources,
                                   const std::vector<Job>& taken, size_t keep, int threads) {
  const std::vector<Eigen::Index>& rows = search.held;
  const auto m = static_cast<Eigen::Index>(rows.size());
  if (m < 100 || sources.size() < 2) return {};
  // Each line's rows, in held order.
  const std::vector<Eigen::Index> starts =
      line_starts(m, [&](Eigen::Index r) { return search.line[rows[static_cast<size_t>(r)]]; });
  // The residual, each line's mean removed.
  Eigen::MatrixXd e(m, 1);
  for (Eigen::Index r = 0; r < m; ++r) e(r, 0) = search.e0[rows[static_cast<size_t>(r)]];
  remove_line_means(starts, e);
  // An orthonormal basis of the base's columns on these rows (line means removed as well).
  Eigen::MatrixXd q(m, 0);
  if (search.a0.cols() > 0) {
    Eigen::MatrixXd a(m, search.a0.cols());
    for (Eigen::Index r = 0; r < m; ++r) a.row(r) = search.a0.row(rows[static_cast<size_t>(r)]);
    a = a.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
    remove_line_means(starts, a);
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
    const Eigen::Index rank = qr.rank();
    q = (qr.householderQ() * Eigen::MatrixXd::Identity(m, rank)).eval();
  }
  const Eigen::Index p = q.cols();
  const Eigen::VectorXd qe = q.transpose() * e.col(0);
  const double ee = e.col(0).squaredNorm() - qe.squaredNorm();
  if (!(ee > 0)) return {};
  // Per row: the direction products B̂iB̂j (xx xy xz yy yz zz), e·B̂i, and the basis times each
  // B̂i (p columns per direction); and B̂ itself, whose sums over a line against a product give
  // the line means of its three columns.
  Eigen::MatrixXd dd(m, 6), ed(m, 3), qd(m, 3 * p), d3(m, 3);
  for (Eigen::Index r = 0; r < m; ++r) {
    const Eigen::Vector3d d = search.inputs.direction.row(rows[static_cast<size_t>(r)]);
    dd.row(r) << d.x() * d.x(), d.x() * d.y(), d.x() * d.z(), d.y() * d.y(), d.y() * d.z(),
        d.z() * d.z();
    ed.row(r) = e(r, 0) * d.transpose();
    d3.row(r) = d.transpose();
    for (int k = 0; k < 3; ++k) qd.row(r).segment(k * p, p) = d[k] * q.row(r);
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
    // The products z = x_a·x_b of later channels b, kBlock at a time (a 5 h flight's held rows
    // times kBlock columns), then their sums against the rows' terms: z²·B̂iB̂j (the Gram of the
    // three columns), z·e·B̂i, z·B̂i·q (their base part).
    constexpr Eigen::Index kBlock = 8;
    Eigen::MatrixXd z;
    for (Eigen::Index a = part; a < n; a += std::max(threads, 1))
      for (Eigen::Index b0 = a + 1; b0 < n; b0 += kBlock) {
        const Eigen::Index nb = std::min(kBlock, n - b0);
        z = x.middleCols(b0, nb).array().colwise() * x.col(a).array();
        const Eigen::MatrixXd s3 = z.transpose() * ed;
        const Eigen::MatrixXd sq = z.transpose() * qd;
        // Each line's sums of the three columns z·B̂i (nb x 3 per line): the scores remove each
        // line's mean from the error, so the columns' line means (a factor that steps from line
        // to line, such as a battery's current, times another's mean) are no part of their Gram.
        std::vector<Eigen::MatrixXd> line_sums(starts.size());
        std::vector<double> line_rows(starts.size());
        for (size_t l = 0; l < starts.size(); ++l) {
          const Eigen::Index to = l + 1 < starts.size() ? starts[l + 1] : m;
          line_rows[l] = static_cast<double>(to - starts[l]);
          line_sums[l] = z.middleRows(starts[l], to - starts[l]).transpose() *
                         d3.middleRows(starts[l], to - starts[l]);
        }
        z = z.array().square().matrix();
        const Eigen::MatrixXd s6 = z.transpose() * dd;
        for (Eigen::Index j = 0; j < nb; ++j) {
          Eigen::Matrix3d g;
          g << s6(j, 0), s6(j, 1), s6(j, 2), s6(j, 1), s6(j, 3), s6(j, 4), s6(j, 2), s6(j, 4),
              s6(j, 5);
          for (size_t l = 0; l < starts.size(); ++l)
            if (line_rows[l] > 0)
              g -= line_sums[l].row(j).transpose() * line_sums[l].row(j) / line_rows[l];
          Eigen::Vector3d h = s3.row(j).transpose();
          if (p > 0) {
            Eigen::MatrixXd c(p, 3);  // the base basis against the three columns
            for (int k = 0; k < 3; ++k) c.col(k) = sq.row(j).segment(k * p, p).transpose();
            g -= c.transpose() * c;
            h -= c.transpose() * qe;
          }
          const double explained = explained_share(g, h, ee);
          if (std::isfinite(explained)) out.push_back({explained, {a, b0 + j}});
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
  // A channel that gates every other (a switch on for part of the flight: any channel times it
  // is that channel's field on a segment of its own) would fill every slot; each channel takes
  // kScreenedPerChannel of them at most, so the pairs fitted name several channels.
  std::vector<Job> jobs;
  std::map<Eigen::Index, size_t> per_channel;
  for (const auto& [explained, pair] : all) {
    if (jobs.size() >= keep) break;
    if (per_channel[pair.first] >= kScreenedPerChannel ||
        per_channel[pair.second] >= kScreenedPerChannel)
      continue;
    const std::string& xa = sources[static_cast<size_t>(pair.first)];
    const std::string& xb = sources[static_cast<size_t>(pair.second)];
    const std::string spec = "field:" + xa + "*" + xb;
    if (already.count(spec)) continue;
    ++per_channel[pair.first];
    ++per_channel[pair.second];
    jobs.push_back({TermSpec(spec), "product of two channels", xa + "*" + xb});
  }
  return jobs;
}

}  // namespace magcomp::diagnose_search
