// magcomp: how well the rows that size a candidate size it: its size beyond the model's own
// columns, that size's jackknife std over blocks of those rows, and how often its channel
// switched there (the measures term_support gives a loop's added terms).
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "magcomp/core/diagnose/term_support.h"
#include "magcomp/core/fit/block_jackknife.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/fit/slow_stage.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

void size_uncertainty(const Search& s, Candidate* c) {
  if (!c->term.shared() || c->family == "lag") return;
  const Eigen::MatrixXd cols = s.columns_of(*c->term.shared());
  const Eigen::Index k = cols.cols();
  if (k == 0) return;
  // The coefficients and their jackknife over the rows that size them: the band-pass fit's
  // stacked rows, or the slow stage's rows (the calibration rows, and the selection lines when
  // slow terms are sized on the held-out lines too), each left out by blocks in time order.
  if (c->slow && (!s.has_slow_stage() || s.slow_runs.empty())) return;
  const std::vector<std::pair<Eigen::Index, Eigen::Index>>& sizing = c->slow ? s.slow_runs : s.runs;
  std::vector<Eigen::Index> rows;  // the sizing rows of the flight, in time order
  for (const auto& [first, last] : sizing)
    for (Eigen::Index i = first; i <= last; ++i) rows.push_back(i);
  Jackknife j;
  Eigen::MatrixXd others = s.a0;  // the model's columns the term is fitted beside
  if (c->slow) {
    others.resize(s.a0.rows(), s.a0.cols() + s.slow_base_cols.cols());
    others << s.a0, s.slow_base_cols;
    std::vector<bool> flight_out(static_cast<size_t>(s.data.size()), false);
    j = block_jackknife(
        static_cast<Eigen::Index>(rows.size()), kJackknifeBlocks,
        [&](const std::vector<bool>& out) {
          for (size_t r = 0; r < rows.size(); ++r)
            flight_out[static_cast<size_t>(rows[r])] = out[r];
          return SlowStage(others, s.e0, sizing, s.fs.lambda, &flight_out).fit(cols);
        });
  } else {
    const Eigen::MatrixXd band = s.band(cols);
    Eigen::MatrixXd x(band.rows(), s.af0.cols() + k);
    x << s.af0, band;
    const double lambda = s.fs.lambda;
    const Jackknife all = block_jackknife(
        x, s.yf, kJackknifeBlocks, [lambda](const Eigen::MatrixXd& g, const Eigen::VectorXd& b) {
          return ridge_normal_solve(g, b, lambda);
        });
    j.coef = all.coef.tail(k);
    j.replicates = all.replicates.bottomRows(k);
    j.sigma = all.sigma.tail(k);
  }
  if (!j.coef.allFinite() || !j.replicates.allFinite()) return;
  // Its size over the flight beyond what the model's other columns take, and that size's std
  // (rms over the rows of sqrt(a_i' cov a_i)), as term_support measures a loop's added terms.
  Eigen::MatrixXd a(cols.rows(), others.cols() + k);
  a << others, cols;
  const Eigen::MatrixXd beyond = beyond_other_columns(a, others.cols(), k);
  const Eigen::MatrixXd cov = j.covariance();
  double sum = 0, sum2 = 0, var = 0, n = 0;
  for (Eigen::Index i = 0; i < beyond.rows(); ++i) {
    if (!beyond.row(i).allFinite()) continue;
    const double v = beyond.row(i).dot(j.coef);
    sum += v;
    sum2 += v * v;
    var += beyond.row(i) * cov * beyond.row(i).transpose();
    n += 1;
  }
  if (n < 2) return;
  c->size_nT = std::sqrt(std::max(0.0, sum2 / n - (sum / n) * (sum / n)));
  c->size_sigma_nT = std::sqrt(var / n);
  c->coefficient_sigma.assign(j.sigma.data(), j.sigma.data() + j.sigma.size());
  const ExprTerm* e = c->term.expr();
  if (e && !e->signal().sources.empty() && s.data.has(e->signal().sources.front())) {
    c->switches_channel = e->signal().sources.front();
    c->switches = channel_switches(s.data.column(c->switches_channel), rows);
  }
}

}  // namespace magcomp::diagnose_search
