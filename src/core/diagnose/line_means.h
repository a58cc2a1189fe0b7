// magcomp: diagnose's screens on held-out rows: each line's mean removed, and the share of an
// error a few columns explain by least squares.
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <vector>

namespace magcomp::diagnose_search {

// The first index of each run of rows with one line number, `line_of(r)` for r in [0, rows).
template <typename LineOf>
std::vector<Eigen::Index> line_starts(Eigen::Index rows, const LineOf& line_of) {
  std::vector<Eigen::Index> out;
  for (Eigen::Index r = 0; r < rows; ++r)
    if (r == 0 || line_of(r) != line_of(r - 1)) out.push_back(r);
  return out;
}

// Each run's mean (line_starts) removed from the columns of `x`.
inline void remove_line_means(const std::vector<Eigen::Index>& starts,
                              Eigen::Ref<Eigen::MatrixXd> x) {
  for (size_t k = 0; k < starts.size(); ++k) {
    const Eigen::Index to = k + 1 < starts.size() ? starts[k + 1] : x.rows();
    if (to <= starts[k]) continue;
    auto block = x.middleRows(starts[k], to - starts[k]);
    block.rowwise() -= block.colwise().mean();
  }
}

// The share of an error of energy `ee` that columns of Gram `g` and products with the error `h`
// explain by least squares (a jitter of 1e-9 of the trace on the diagonal); NaN when undefined.
template <typename Gram, typename Products>
double explained_share(Gram g, const Products& h, double ee) {
  g.diagonal().array() += 1e-9 * std::max(g.trace(), 1e-300);
  return h.dot(g.ldlt().solve(h)) / ee;
}

}  // namespace magcomp::diagnose_search
