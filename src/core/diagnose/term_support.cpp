// magcomp: the support of the terms a diagnosis added.
#include "magcomp/core/diagnose/term_support.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {

int channel_switches(const Eigen::VectorXd& x, const std::vector<Eigen::Index>& rows) {
  std::vector<double> v;
  for (Eigen::Index i = 0; i < x.size(); ++i)
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

Eigen::MatrixXd beyond_other_columns(const Eigen::MatrixXd& a, Eigen::Index from, Eigen::Index n) {
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < a.rows(); ++i)
    if (a.row(i).allFinite()) rows.push_back(i);
  const Eigen::Index k = a.cols() - n + 1;
  if (static_cast<Eigen::Index>(rows.size()) <= 2 * k) return a.middleCols(from, n);
  Eigen::MatrixXd out = Eigen::MatrixXd::Constant(a.rows(), n, NAN);
  Eigen::MatrixXd others(static_cast<Eigen::Index>(rows.size()), k), block(others.rows(), n);
  for (Eigen::Index r = 0; r < others.rows(); ++r) {
    const Eigen::Index i = rows[static_cast<size_t>(r)];
    others.row(r) << a.row(i).head(from), a.row(i).tail(a.cols() - from - n), 1.0;
    block.row(r) = a.row(i).segment(from, n);
  }
  // Scaled to unit columns, so that a column in nT beside one in units of a channel stay apart.
  Eigen::VectorXd scale = others.colwise().norm().transpose();
  for (Eigen::Index c = 0; c < k; ++c) scale[c] = scale[c] > 0 ? 1.0 / scale[c] : 0.0;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(others * scale.asDiagonal());
  qr.setThreshold(1e-10);
  const Eigen::MatrixXd fitted = others * scale.asDiagonal() * qr.solve(block);
  for (Eigen::Index r = 0; r < others.rows(); ++r)
    out.row(rows[static_cast<size_t>(r)]) = block.row(r) - fitted.row(r);
  return out;
}

std::vector<TermSupport> term_support(const Model& model, const Model& start,
                                      const FlightData& data) {
  return term_support(model, start, std::vector<const FlightData*>{&data});
}

std::vector<TermSupport> term_support(const Model& model, const Model& start,
                                      const std::vector<const FlightData*>& flights) {
  std::vector<TermSupport> out;
  if (!model.fitted()) return out;
  const auto terms = model.make_terms();
  // The coefficients' covariance by the jackknife over blocks of the calibration rows (it holds
  // for a correlated residual and for a column a few events excite), else the fit's own.
  Eigen::MatrixXd cov = coefficient_jackknife_covariance(model, flights);
  if (cov.size() == 0) cov = model.report.coefficient_covariance;
  const bool has_cov = cov.rows() == model.coefficients.size() && cov.cols() == cov.rows();
  // Per added term: its place in the columns, and the sums over every flight's rows.
  struct Sums {
    Eigen::Index from = 0, n = 0;
    double sum = 0, sum2 = 0, var = 0, count = 0;
    bool sized = false;
    bool slow = false;  // fitted by the slow stage: no covariance here
  };
  std::vector<Sums> sums;
  Eigen::Index first = 0;
  for (size_t k = 0; k < terms.size(); ++k) {
    const Eigen::Index n = static_cast<Eigen::Index>(terms[k]->column_names().size());
    const TermSpec& spec = model.terms[k];
    const Eigen::Index from = first;
    first += n;
    if (std::find(start.terms.begin(), start.terms.end(), spec) != start.terms.end()) continue;
    TermSupport s;
    s.term = spec;
    const ExprTerm* e = spec.expr();
    if (e && !e->signal().sources.empty()) s.channel = e->signal().sources.front();
    // The twins of each recorded channel of the term, as the flights show them, and whether it
    // follows the flights' time.
    if (e)
      for (const std::string& x : e->required_fields()) {
        for (ChannelTwin& t : channel_twins(x, flights)) s.twins.push_back(std::move(t));
        for (TimeTrend& t : time_trend(x, flights)) s.time_trends.push_back(std::move(t));
      }
    // A low-pass at the top of the scan the longest flight allows: a drift, not a response.
    if (const double tau_s = slowest_low_pass_s(spec); tau_s > 0) {
      double top_s = 0;
      for (const FlightData* f : flights)
        if (f->size() >= 2)
          top_s = std::max(top_s, longest_scanned_time_constant_s(
                                      f->dt_s(), f->tt()[f->size() - 1] - f->tt()[0]));
      if (at_longest_scanned_time_constant(tau_s, top_s)) s.slowest_time_constant_s = top_s;
    }
    out.push_back(s);
    Sums m;
    m.from = from;
    m.n = n;
    m.sized = from + n <= model.coefficients.size();
    m.slow =
        std::find(model.slow_terms.begin(), model.slow_terms.end(), spec) != model.slow_terms.end();
    out.back().on_lines = m.slow && !model.fit.slow_lines.empty();
    sums.push_back(m);
  }
  for (const FlightData* flight : flights) {
    const FlightData& data = *flight;
    std::vector<Eigen::Index> rows;
    if (!model.fit.lines.empty() || !model.fit.windows.empty())
      rows = data.select(model.fit.lines, model.fit.windows);
    if (rows.empty())
      for (Eigen::Index i = 0; i < data.size(); ++i) rows.push_back(i);
    // A slow term sized on the lines too: its rows are those and the calibration rows.
    std::vector<Eigen::Index> slow_rows;
    if (!model.fit.slow_lines.empty()) {
      std::vector<double> lines = model.fit.lines;
      lines.insert(lines.end(), model.fit.slow_lines.begin(), model.fit.slow_lines.end());
      slow_rows = data.select(lines, model.fit.windows);
    }
    const Eigen::MatrixXd a = design_matrix(model, data);
    for (size_t k = 0; k < out.size(); ++k) {
      TermSupport& s = out[k];
      if (!s.channel.empty() && data.has(s.channel))
        s.switches = std::max(s.switches, 0) +
                     channel_switches(data.column(s.channel), s.on_lines ? slow_rows : rows);
      Sums& m = sums[k];
      if (!m.sized || m.from + m.n > a.cols()) {
        m.sized = false;
        continue;
      }
      const Eigen::MatrixXd block = beyond_other_columns(a, m.from, m.n);
      const Eigen::VectorXd contribution = block * model.coefficients.segment(m.from, m.n);
      const Eigen::MatrixXd sigma =
          has_cov ? cov.block(m.from, m.from, m.n, m.n) : Eigen::MatrixXd();
      for (Eigen::Index i = 0; i < block.rows(); ++i) {
        if (!contribution.row(i).allFinite() || !block.row(i).allFinite()) continue;
        m.sum += contribution[i];
        m.sum2 += contribution[i] * contribution[i];
        if (has_cov && !m.slow) m.var += block.row(i) * sigma * block.row(i).transpose();
        ++m.count;
      }
    }
  }
  for (size_t k = 0; k < out.size(); ++k) {
    const Sums& m = sums[k];
    if (!m.sized || m.count <= 1) continue;
    const double mean = m.sum / m.count;
    out[k].size_nT = std::sqrt(std::max(0.0, m.sum2 / m.count - mean * mean));
    if (has_cov && !m.slow) out[k].size_sigma_nT = std::sqrt(m.var / m.count);
  }
  return out;
}

std::string time_trend_note(const TermSupport& s) {
  if (s.time_trends.empty()) return "";
  std::string names, shares;
  for (size_t k = 0; k < s.time_trends.size(); ++k) {
    const char* sep = k == 0 ? "" : k + 1 == s.time_trends.size() ? " and " : ", ";
    names += sep + s.time_trends[k].channel;
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%s%.2f %%", k == 0 ? "" : ", ", 100 * s.time_trends[k].share);
    shares += buf;
  }
  const bool one = s.time_trends.size() == 1;
  char buf[900];
  std::snprintf(buf, sizeof(buf),
                "%s %s a smooth curve of time on these flights (a cubic in time gives %s of the "
                "variance of %s %.0f s means): a term of %s writes any effect of that shape (a "
                "charge, a warm-up, another source's drift), and these flights cannot say that "
                "%s %s it; a flight on which %s another course tells",
                names.c_str(), one ? "follows" : "follow", shares.c_str(), one ? "its" : "their",
                kTimeTrendBlock_s, one ? "it" : "them", names.c_str(), one ? "carries" : "carry",
                one ? "it runs" : "they run");
  return buf;
}

std::string slow_edge_note(const TermSupport& s) {
  if (!std::isfinite(s.slowest_time_constant_s)) return "";
  char buf[500];
  std::snprintf(buf, sizeof(buf),
                "its time constant is the longest these flights tell apart (%.0f s): it stands for "
                "a drift at least that slow, which a slow trend of any "
                "channel may match as well as %s's; a second flight (--validate NEXT.h5) tells "
                "whether %s carries it",
                s.slowest_time_constant_s, s.channel.empty() ? "its channel" : s.channel.c_str(),
                s.channel.empty() ? "its channel" : s.channel.c_str());
  return buf;
}

std::string twins_note(const TermSupport& s) {
  if (s.twins.empty()) return "";
  std::string out = "these flights cannot tell ";
  for (size_t k = 0; k < s.twins.size(); ++k) {
    const ChannelTwin& t = s.twins[k];
    char buf[200];
    std::snprintf(buf, sizeof(buf), "%s%s from %s (r %.5f)", k ? ", nor " : "", t.channel.c_str(),
                  t.twin.c_str(), t.correlation);
    out += buf;
  }
  char tail[120];
  std::snprintf(tail, sizeof(tail), ", smoothed over %.0f s: the effect may be either's",
                kTwinWindow_s);
  return out + tail;
}

std::string support_note(const TermSupport& s, int few_switches, const std::string& rows_in) {
  if (s.channel.empty() || s.switches < 0) return "";
  const std::string rows =
      s.on_lines ? "the calibration rows and the lines beside them (fit.slow_lines)" : rows_in;
  char buf[400];
  if (s.switches < few_switches) {
    if (std::isfinite(s.size_sigma_nT))
      std::snprintf(buf, sizeof(buf),
                    "%s switched %d times on %s: its size, %.3g nT, is uncertain to +-%.2g nT",
                    s.channel.c_str(), s.switches, rows.c_str(), s.size_nT, s.size_sigma_nT);
    else
      std::snprintf(buf, sizeof(buf), "%s switched %d times on %s: its size, %.3g nT, is uncertain",
                    s.channel.c_str(), s.switches, rows.c_str(), s.size_nT);
    return buf;
  }
  // A size the calibration rows do not determine (within two sigma of none): the term fits
  // something its channel only stands in for (a slow drift of the fit, another channel).
  if (std::isfinite(s.size_sigma_nT) && s.size_nT < 2.0 * s.size_sigma_nT) {
    std::snprintf(buf, sizeof(buf),
                  "its size, %.3g nT, is not determined by %s (+-%.2g nT over blocks of them): %s "
                  "may stand in for another effect (a slow drift of the fit, another channel)",
                  s.size_nT, rows.c_str(), s.size_sigma_nT, s.channel.c_str());
    return buf;
  }
  return "";
}

}  // namespace magcomp
