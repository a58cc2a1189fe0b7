// magcomp: candidate ranking by held-out refits, and the residual-channel association view.
#include "magcomp/core/diagnose.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <set>
#include <sstream>

#include "magcomp/core/error.h"
#include "magcomp/core/evaluation.h"
#include "magcomp/core/timeseries.h"

namespace magcomp {
namespace {

bool is_channel(const std::string& name) {
  return name.rfind("cur_", 0) == 0 || name.rfind("vol_", 0) == 0;
}

std::string family(const std::string& spec) {
  for (const char* f : {"permanent", "induced", "eddy"}) {
    if (spec.rfind(f, 0) == 0) return f;
  }
  return spec;
}

// Ranks with ties averaged (for Spearman).
Eigen::VectorXd ranks(const Eigen::VectorXd& x) {
  std::vector<Eigen::Index> order(static_cast<size_t>(x.size()));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](Eigen::Index a, Eigen::Index b) { return x[a] < x[b]; });
  Eigen::VectorXd r(x.size());
  for (size_t i = 0; i < order.size();) {
    size_t j = i;
    while (j + 1 < order.size() && x[order[j + 1]] == x[order[i]]) ++j;
    const double avg = 0.5 * static_cast<double>(i + j);
    for (size_t k = i; k <= j; ++k) r[order[k]] = avg;
    i = j + 1;
  }
  return r;
}

double pearson(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  const Eigen::ArrayXd da = a.array() - a.mean(), db = b.array() - b.mean();
  const double den = std::sqrt((da * da).sum() * (db * db).sum());
  return den > 0 ? (da * db).sum() / den : 0.0;
}

// Mutual information in bits with equal-frequency bins on both variables.
double mutual_information(const Eigen::VectorXd& a, const Eigen::VectorXd& b, int bins) {
  const Eigen::Index n = a.size();
  if (n < bins * 4) return 0.0;
  const Eigen::VectorXd ra = ranks(a), rb = ranks(b);
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

std::vector<std::string> candidate_terms(const Model& model, const FlightData& data,
                                         std::vector<std::string>* notes) {
  std::set<std::string> have(model.terms.begin(), model.terms.end());
  std::set<std::string> families;
  for (const auto& t : model.terms) families.insert(family(t));
  std::vector<std::string> out;
  for (const char* f : {"permanent", "induced", "eddy"}) {
    if (!families.count(f)) out.push_back(f);
  }
  if (!have.count("second_order")) out.push_back("second_order");
  for (const char* rate : {"pitch_rate", "roll_rate", "yaw_rate"}) {
    const std::string spec = std::string("rate:") + rate;
    if (data.has(rate) && !have.count(spec)) out.push_back(spec);
  }
  for (const std::string& name : data.names()) {
    if (!is_channel(name)) continue;
    const Eigen::VectorXd& x = data.column(name);
    double lo = INFINITY, hi = -INFINITY;
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      if (std::isfinite(x[i])) {
        lo = std::min(lo, x[i]);
        hi = std::max(hi, x[i]);
      }
    }
    if (!(hi > lo)) {
      if (notes) notes->push_back("channel '" + name + "' is constant (or all NaN); skipped");
      continue;
    }
    for (const char* kind : {"current:", "dcurrent:"}) {
      const std::string spec = kind + name;
      if (!have.count(spec)) out.push_back(spec);
    }
  }
  return out;
}

Diagnosis diagnose(const Model& model, const FlightData& data, const std::string& truth_name) {
  if (!data.has(truth_name)) {
    throw Error(data.source() + ": reference field '" + truth_name + "' not found");
  }
  const Eigen::VectorXd& truth = data.column(truth_name);
  if (!truth.array().isFinite().any()) {
    throw Error(data.source() + ": reference field '" + truth_name + "' holds no finite sample");
  }
  Diagnosis dx;
  const Eigen::MatrixXd a0 = design_matrix(model, data);  // names a missing sensor field
  const Eigen::VectorXd scalar = aligned_scalar(model, data);
  const Eigen::VectorXd line =
      data.has("line") ? data.column("line") : Eigen::VectorXd::Zero(data.size());
  const Eigen::Index n = data.size();
  const double dt = data.dt_s();

  // --- The split: fit rows and held-out rows.
  FitSettings fs = model.fit;
  std::vector<bool> in_fit(static_cast<size_t>(n), false);
  std::vector<std::pair<Eigen::Index, Eigen::Index>> runs;
  Eigen::VectorXd y;
  bool own_calibration = false;
  if (fs.method == "bandpass" && !(fs.lines.empty() && fs.windows.empty())) {
    y = scalar;
    runs = calibration_runs(fs, data, a0, y, nullptr);
    own_calibration = !runs.empty();
  }
  if (own_calibration) {
    for (Eigen::Index i : data.select(fs.lines, fs.windows)) in_fit[static_cast<size_t>(i)] = true;
    dx.split = "fit on the model's calibration segments (band-pass), held out: every other line";
  } else {
    std::vector<double> lines;
    for (Eigen::Index i = 0; i < n; ++i) {
      if (std::isfinite(line[i]) &&
          (lines.empty() || std::find(lines.begin(), lines.end(), line[i]) == lines.end())) {
        lines.push_back(line[i]);
      }
    }
    std::sort(lines.begin(), lines.end());
    if (lines.size() < 2) {
      throw Error(data.source() + ": diagnose needs two lines or the model's calibration segments");
    }
    fs.method = "reference";
    fs.reference = truth_name;
    fs.windows.clear();
    fs.lines.clear();
    for (size_t k = 0; k < lines.size(); k += 2) fs.lines.push_back(lines[k]);
    y = scalar - truth;
    runs = calibration_runs(fs, data, a0, y, nullptr);
    for (Eigen::Index i : data.select(fs.lines, {})) in_fit[static_cast<size_t>(i)] = true;
    dx.split = "reference fit against " + truth_name + " on every other line, held out: the rest";
  }
  if (runs.empty()) throw Error(data.source() + ": no usable fit samples for diagnose");

  // --- The base model, refitted; its normal equations are reused for every candidate.
  const Eigen::MatrixXd af0 = stack_runs(fs, dt, a0, runs);
  const Eigen::VectorXd yf = stack_runs(fs, dt, y, runs).col(0);
  dx.fit_samples = yf.size();
  const Eigen::Index p0 = a0.cols();
  const Eigen::MatrixXd g00 = af0.transpose() * af0;
  const Eigen::VectorXd b0 = af0.transpose() * yf;
  const double jitter = 1e-12 * std::max(g00.trace() / static_cast<double>(p0), 1e-300);
  auto solve = [&](const Eigen::MatrixXd& g, const Eigen::VectorXd& b) {
    Eigen::MatrixXd r = g;
    r.diagonal().array() += fs.lambda + jitter;
    return Eigen::VectorXd(r.ldlt().solve(b));
  };
  const Eigen::VectorXd c0 = solve(g00, b0);
  const Eigen::VectorXd e0 = scalar - truth - a0 * c0;  // error of the refitted model
  std::vector<Eigen::Index> held;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!in_fit[static_cast<size_t>(i)] && std::isfinite(e0[i]) && std::isfinite(line[i]))
      held.push_back(i);
  }
  if (held.size() < 10) throw Error(data.source() + ": too few held-out samples for diagnose");
  dx.heldout_samples = static_cast<Eigen::Index>(held.size());
  auto heldout_std = [&](const Eigen::VectorXd& e) {
    Eigen::VectorXd r(static_cast<Eigen::Index>(held.size())), g(r.size());
    for (size_t k = 0; k < held.size(); ++k) {
      r[static_cast<Eigen::Index>(k)] = e[held[k]];
      g[static_cast<Eigen::Index>(k)] = line[held[k]];
    }
    return pooled_std(r, g);
  };
  dx.baseline_std_nT = heldout_std(e0);

  // --- Every candidate: add its columns, refit, measure on the held-out samples.
  const TermInputs inputs = make_term_inputs(data, model.vector, model.bt_scale_nT);
  for (const std::string& spec : candidate_terms(model, data, &dx.notes)) {
    const auto term = make_term(spec);
    const auto k = static_cast<Eigen::Index>(term->column_names().size());
    Eigen::MatrixXd c(n, k);
    term->build(inputs, c);
    bool nan_in_fit = false;
    for (const auto& [first, last] : runs) {
      if (!c.middleRows(first, last - first + 1).allFinite()) nan_in_fit = true;
    }
    if (nan_in_fit) {
      dx.notes.push_back("candidate '" + spec + "' has NaN in the fit samples; skipped");
      continue;
    }
    const Eigen::MatrixXd cf = stack_runs(fs, dt, c, runs);
    if (!(cf.norm() > 0)) {
      dx.notes.push_back("candidate '" + spec + "' is not excited in the fit samples; skipped");
      continue;
    }
    Eigen::MatrixXd g(p0 + k, p0 + k);
    g.topLeftCorner(p0, p0) = g00;
    g.topRightCorner(p0, k) = af0.transpose() * cf;
    g.bottomLeftCorner(k, p0) = g.topRightCorner(p0, k).transpose();
    g.bottomRightCorner(k, k) = cf.transpose() * cf;
    Eigen::VectorXd b(p0 + k);
    b << b0, cf.transpose() * yf;
    const Eigen::VectorXd coef = solve(g, b);
    Eigen::VectorXd contribution = c * coef.tail(k);
    for (Eigen::Index i = 0; i < n; ++i) {
      if (!std::isfinite(contribution[i])) contribution[i] = 0.0;  // no data: no correction
    }
    const Eigen::VectorXd e = scalar - truth - a0 * coef.head(p0) - contribution;
    Candidate cand;
    cand.term = term->spec();
    cand.effect = term->effect();
    const auto colon = spec.find(':');
    cand.channel = colon == std::string::npos ? "" : spec.substr(colon + 1);
    cand.std_after_nT = heldout_std(e);
    cand.explained_fraction =
        dx.baseline_std_nT > 0 ? 1.0 - std::pow(cand.std_after_nT / dx.baseline_std_nT, 2) : 0.0;
    std::ostringstream est;
    est.precision(3);
    if (spec.rfind("current:", 0) == 0) {
      est << "body field " << coef.tail(k).norm() << " nT/A";
    } else if (spec.rfind("dcurrent:", 0) == 0) {
      est << "body field " << coef.tail(k).norm() << " nT per A/s";
    }
    cand.estimate = est.str();
    dx.candidates.push_back(cand);
  }
  // --- Lag: the raw scalar realigned by tau (absolute); only the target changes, so each trial is
  // one filter of y and one small solve. Coarse grid over the model's lag +-1 s, then
  // golden-section refinement. A model that has a lag gets it re-estimated (lag:<new> replaces it).
  {
    const Eigen::VectorXd& raw = data.column(model.scalar);
    const double current_lag = model.scalar_lag_s();
    auto lag_std = [&](double tau) {
      const Eigen::VectorXd s = shift_samples(raw, -tau / dt);  // NaN past the ends: not scored
      const Eigen::VectorXd s_held = shift_samples(raw, -tau / dt, true);  // filters need no NaN
      const Eigen::VectorXd yl = own_calibration ? s_held : Eigen::VectorXd(s_held - truth);
      const Eigen::VectorXd ylf = stack_runs(fs, dt, yl, runs).col(0);
      const Eigen::VectorXd c = solve(g00, af0.transpose() * ylf);
      return heldout_std(s - truth - a0 * c);
    };
    double best_tau = current_lag, best = dx.baseline_std_nT;
    for (double tau = current_lag - 1.0; tau <= current_lag + 1.0 + 1e-9; tau += 0.05) {
      const double v = lag_std(tau);
      if (v < best) {
        best = v;
        best_tau = tau;
      }
    }
    double lo = best_tau - 0.05, hi = best_tau + 0.05;
    const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
    double x1 = hi - phi * (hi - lo), x2 = lo + phi * (hi - lo);
    double f1 = lag_std(x1), f2 = lag_std(x2);
    while (hi - lo > 0.002) {
      if (f1 < f2) {
        hi = x2;
        x2 = x1;
        f2 = f1;
        x1 = hi - phi * (hi - lo);
        f1 = lag_std(x1);
      } else {
        lo = x1;
        x1 = x2;
        f1 = f2;
        x2 = lo + phi * (hi - lo);
        f2 = lag_std(x2);
      }
    }
    const double tau = std::round(0.5 * (lo + hi) * 100.0) / 100.0;  // 0.01 s, as the term says
    if (std::abs(tau - current_lag) >= 0.005) {
      const auto term = make_term("lag:" + std::to_string(tau));
      Candidate cand;
      cand.term = term->spec();
      cand.effect = term->effect();
      cand.std_after_nT = lag_std(tau);
      cand.explained_fraction =
          dx.baseline_std_nT > 0 ? 1.0 - std::pow(cand.std_after_nT / dx.baseline_std_nT, 2) : 0.0;
      std::ostringstream est;
      est.precision(3);
      est << "scalar late by " << tau << " s";
      if (current_lag != 0.0) est << " (model: " << current_lag << ")";
      cand.estimate = est.str();
      dx.candidates.push_back(cand);
    }
  }
  std::sort(dx.candidates.begin(), dx.candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.std_after_nT < b.std_after_nT; });

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
    const Eigen::VectorXd& x = data.column(name);
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
    a.spearman = pearson(rr, ranks(v));
    a.mutual_information_bits = mutual_information(r, v, 16);
    dx.associations.push_back(a);
  }
  std::sort(dx.associations.begin(), dx.associations.end(),
            [](const ChannelAssociation& a, const ChannelAssociation& b) {
              return std::abs(a.spearman) > std::abs(b.spearman);
            });
  return dx;
}

}  // namespace magcomp
