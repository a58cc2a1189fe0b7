// magcomp: the held-out residual against every channel (Pearson, Spearman, mutual information).
#include "magcomp/core/diagnose/associations.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <set>

#include "magcomp/core/math/correlation.h"

namespace magcomp {
namespace {

// Mutual information in bits with equal-frequency bins on both variables, from their ranks
// (ranks(): 0 .. n - 1, ties averaged).
double mutual_information_of_ranks(const Eigen::VectorXd& ra, const Eigen::VectorXd& rb, int bins) {
  const Eigen::Index n = ra.size();
  if (n < bins * 4) return 0.0;
  Eigen::MatrixXd joint = Eigen::MatrixXd::Zero(bins, bins);
  for (Eigen::Index i = 0; i < n; ++i) {
    const int ia = std::min(bins - 1, static_cast<int>(ra[i] * bins / static_cast<double>(n)));
    const int ib = std::min(bins - 1, static_cast<int>(rb[i] * bins / static_cast<double>(n)));
    joint(ia, ib) += 1.0;
  }
  joint /= static_cast<double>(n);
  const Eigen::VectorXd pa = joint.rowwise().sum(), pb = joint.colwise().sum().transpose();
  double mi = 0;
  for (int i = 0; i < bins; ++i)
    for (int j = 0; j < bins; ++j)
      if (joint(i, j) > 0) mi += joint(i, j) * std::log2(joint(i, j) / (pa[i] * pb[j]));
  return mi;
}

}  // namespace

std::vector<ChannelAssociation> residual_associations(const FlightData& data,
                                                      const std::vector<Eigen::Index>& held,
                                                      const Eigen::VectorXd& e0,
                                                      const Eigen::VectorXd& line,
                                                      const std::string& truth_name) {
  std::vector<ChannelAssociation> associations;
  // --- Pre-selection view: the held-out residual (line means removed) against every channel.
  std::map<double, std::pair<double, double>> line_mean;
  for (Eigen::Index i : held) {
    auto& m = line_mean[line[i]];
    m.first += e0[i];
    m.second += 1;
  }
  const size_t stride = std::max<size_t>(1, held.size() / 20000);
  std::vector<Eigen::Index> rows;
  for (size_t k = 0; k < held.size(); k += stride) rows.push_back(held[k]);
  Eigen::VectorXd r(static_cast<Eigen::Index>(rows.size()));
  for (size_t k = 0; k < rows.size(); ++k) {
    const auto& m = line_mean[line[rows[k]]];
    r[static_cast<Eigen::Index>(k)] = e0[rows[k]] - m.first / m.second;
  }
  const Eigen::VectorXd rr = ranks(r);
  static const std::set<std::string> kSkip = {"tt", "line", "flight", "year", "doy", "N", "dt"};
  for (const std::string& name : data.names()) {
    if (kSkip.count(name) || name.rfind("mag_", 0) == 0 || name == truth_name) continue;
    const auto x = data.column(name);
    Eigen::VectorXd v(r.size());
    bool finite = true;
    for (size_t k = 0; k < rows.size(); ++k) {
      v[static_cast<Eigen::Index>(k)] = x[rows[k]];
      finite = finite && std::isfinite(x[rows[k]]);
    }
    if (!finite || !(v.maxCoeff() > v.minCoeff())) continue;
    ChannelAssociation a;
    a.channel = name;
    a.pearson = pearson(r, v);
    const Eigen::VectorXd rv = ranks(v);  // once per channel: Spearman and the bins share it
    a.spearman = pearson(rr, rv);
    a.mutual_information_bits = mutual_information_of_ranks(rr, rv, 16);
    associations.push_back(a);
  }
  std::sort(associations.begin(), associations.end(),
            [](const ChannelAssociation& a, const ChannelAssociation& b) {
              return std::abs(a.spearman) > std::abs(b.spearman);
            });
  return associations;
}

}  // namespace magcomp
