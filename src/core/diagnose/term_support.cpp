// magcomp: the support of the terms a diagnosis added.
#include "magcomp/core/diagnose/term_support.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "magcomp/core/model/terms_expr.h"

namespace magcomp {
namespace {

// Crossings of x between its lower and upper quarter (of its 1-99 % range on `rows`).
int switches_on(const Eigen::VectorXd& x, const std::vector<Eigen::Index>& rows) {
  std::vector<double> v;
  for (Eigen::Index i : rows)
    if (std::isfinite(x[i])) v.push_back(x[i]);
  if (v.size() < 10) return 0;
  std::sort(v.begin(), v.end());
  const double lo = v[v.size() / 100], hi = v[v.size() - 1 - v.size() / 100];
  if (!(hi > lo)) return 0;
  const double low = lo + 0.25 * (hi - lo), high = lo + 0.75 * (hi - lo);
  int state = 0, count = 0;  // -1 low, +1 high
  for (Eigen::Index i : rows) {
    if (!std::isfinite(x[i])) continue;
    const int s = x[i] <= low ? -1 : x[i] >= high ? 1 : 0;
    if (s != 0 && state != 0 && s != state) ++count;
    if (s != 0) state = s;
  }
  return count;
}

}  // namespace

std::vector<TermSupport> term_support(const Model& model, const Model& start,
                                      const FlightData& data) {
  std::vector<TermSupport> out;
  if (!model.fitted()) return out;
  std::vector<Eigen::Index> rows;
  if (!model.fit.lines.empty() || !model.fit.windows.empty())
    rows = data.select(model.fit.lines, model.fit.windows);
  if (rows.empty())
    for (Eigen::Index i = 0; i < data.size(); ++i) rows.push_back(i);
  const auto terms = model.make_terms();
  const Eigen::MatrixXd a = design_matrix(model, data);
  const Eigen::MatrixXd& cov = model.report.coefficient_covariance;
  Eigen::Index first = 0;
  for (size_t k = 0; k < terms.size(); ++k) {
    const Eigen::Index n = static_cast<Eigen::Index>(terms[k]->column_names().size());
    const std::string& spec = model.terms[k];
    const Eigen::Index from = first;
    first += n;
    if (std::find(start.terms.begin(), start.terms.end(), spec) != start.terms.end()) continue;
    TermSupport s;
    s.term = spec;
    const auto e = parse_expr_term(spec);
    if (e && !e->signal().sources.empty()) {
      s.channel = e->signal().sources.front();
      if (data.has(s.channel)) s.switches = switches_on(data.column(s.channel), rows);
    }
    if (from + n > a.cols() || from + n > model.coefficients.size()) {
      out.push_back(s);
      continue;
    }
    const Eigen::MatrixXd block = a.middleCols(from, n);
    const Eigen::VectorXd contribution = block * model.coefficients.segment(from, n);
    double sum = 0, sum2 = 0, var = 0, count = 0;
    const bool has_cov = cov.rows() == model.coefficients.size() && cov.cols() == cov.rows();
    const Eigen::MatrixXd sigma = has_cov ? cov.block(from, from, n, n) : Eigen::MatrixXd();
    for (Eigen::Index i = 0; i < block.rows(); ++i) {
      if (!contribution.row(i).allFinite() || !block.row(i).allFinite()) continue;
      sum += contribution[i];
      sum2 += contribution[i] * contribution[i];
      if (has_cov) var += block.row(i) * sigma * block.row(i).transpose();
      ++count;
    }
    if (count > 1) {
      const double mean = sum / count;
      s.size_nT = std::sqrt(std::max(0.0, sum2 / count - mean * mean));
      if (has_cov) s.size_sigma_nT = std::sqrt(var / count);
    }
    out.push_back(s);
  }
  return out;
}

std::string support_note(const TermSupport& s, int few_switches) {
  if (s.channel.empty() || s.switches < 0 || s.switches >= few_switches) return "";
  char buf[320];
  if (std::isfinite(s.size_sigma_nT))
    std::snprintf(buf, sizeof(buf),
                  "%s switched %d times on the calibration rows: its size, %.3g nT, is uncertain "
                  "to +-%.2g nT (the fit's noise; more with a broadband error)",
                  s.channel.c_str(), s.switches, s.size_nT, s.size_sigma_nT);
  else
    std::snprintf(buf, sizeof(buf),
                  "%s switched %d times on the calibration rows: its size, %.3g nT, is uncertain",
                  s.channel.c_str(), s.switches, s.size_nT);
  return buf;
}

}  // namespace magcomp
