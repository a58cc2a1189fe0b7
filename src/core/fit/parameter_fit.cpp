// magcomp: profile least squares for the nonlinear parameters of terms.
#include "magcomp/core/fit/parameter_fit.h"

#include "magcomp/core/fit/model_fit.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>

#include "magcomp/core/error.h"
#include "magcomp/core/math/tall_products.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {

FitRowSet::FitRowSet(const Model& model, const std::vector<const FlightData*>& flights,
                     std::vector<std::string>* warnings)
    : fit_(model.fit), flights_(flights) {
  std::vector<Eigen::VectorXd> ys;
  for (const FlightData* f : flights) {
    const Eigen::MatrixXd a = design_matrix(model, *f);
    const Eigen::VectorXd y = fit_target(model, *f);
    runs_.push_back(calibration_runs(fit_, *f, a, y, warnings));
    segments_ += static_cast<int>(runs_.back().size());
    ys.push_back(runs_.back().empty()
                     ? Eigen::VectorXd()
                     : Eigen::VectorXd(stack_runs(fit_, f->dt_s(), y, runs_.back()).col(0)));
  }
  Eigen::Index n = 0;
  for (const auto& y : ys) n += y.size();
  y_.resize(n);
  n = 0;
  for (const auto& y : ys) {
    y_.segment(n, y.size()) = y;
    n += y.size();
  }
}

Eigen::MatrixXd FitRowSet::stack(const std::vector<Eigen::MatrixXd>& per_flight) const {
  const Eigen::Index k = per_flight.empty() ? 0 : per_flight[0].cols();
  Eigen::MatrixXd out(y_.size(), k);
  Eigen::Index r = 0;
  for (size_t f = 0; f < flights_.size(); ++f) {
    if (runs_[f].empty()) continue;
    const Eigen::MatrixXd x =
        per_flight[f].unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
    const Eigen::MatrixXd s = stack_runs(fit_, flights_[f]->dt_s(), x, runs_[f]);
    out.middleRows(r, s.rows()) = s;
    r += s.rows();
  }
  return out;
}

Eigen::VectorXd ridge_normal_solve(const Eigen::MatrixXd& g, const Eigen::VectorXd& b,
                                   double lambda) {
  // (G + lambda I) c = b, solved on the column-normalised system by eigen-decomposition with
  // directions below 1e-10 of the largest dropped: exactly collinear columns (second_order's
  // quartics hold the induced quadratics) share their coefficients instead of blowing up.
  Eigen::MatrixXd r = g;
  r.diagonal().array() += lambda;
  const Eigen::VectorXd scale = r.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd rn = scale.asDiagonal() * r * scale.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(rn);
  const Eigen::VectorXd ev = es.eigenvalues();
  const double cut = 1e-10 * std::max(ev.maxCoeff(), 1e-300);
  const Eigen::VectorXd bn = es.eigenvectors().transpose() * scale.asDiagonal() * b;
  Eigen::VectorXd z(bn.size());
  for (Eigen::Index i = 0; i < bn.size(); ++i) z[i] = ev[i] > cut ? bn[i] / ev[i] : 0.0;
  return scale.asDiagonal() * (es.eigenvectors() * z);
}

RidgeProfile::RidgeProfile(const Eigen::MatrixXd& base, const Eigen::VectorXd& y, double lambda)
    : base_(base), y_(y), lambda_(lambda) {
  g00_ = base.transpose() * base;
  b0_ = base.transpose() * y;
  yy_ = y.squaredNorm();
}

Eigen::VectorXd RidgeProfile::solve(const Eigen::MatrixXd& cand, double* rss) const {
  const Eigen::Index p = g00_.cols(), k = cand.cols();
  Eigen::MatrixXd g(p + k, p + k);
  g.topLeftCorner(p, p) = g00_;
  if (k > 0) {
    g.topRightCorner(p, k) = transpose_product(base_, cand);
    g.bottomLeftCorner(k, p) = g.topRightCorner(p, k).transpose();
    g.bottomRightCorner(k, k) = gram(cand);
  }
  Eigen::VectorXd b(p + k);
  b.head(p) = b0_;
  if (k > 0) b.tail(k) = cand.transpose() * y_;
  const Eigen::VectorXd c = ridge_normal_solve(g, b, lambda_);
  if (rss) {
    // From the rows themselves: the normal equations' y'y - 2c'b + c'Gc loses the residual to
    // rounding where the base's columns nearly coincide (1e-7 of it on TL's eighteen).
    Eigen::VectorXd e = y_ - base_ * c.head(p);
    if (k > 0) e -= cand * c.tail(k);
    *rss = e.squaredNorm();
  }
  return c;
}

Eigen::VectorXd signal_sources_product(const SignalExpr& signal, const FlightData& data,
                                       size_t* missing) {
  Eigen::VectorXd v = Eigen::VectorXd::Ones(data.size());
  size_t absent = 0;
  for (const auto& name : signal.sources) {
    if (!data.has(name)) {
      ++absent;
      continue;
    }
    v.array() *= data.column(name).array();
  }
  if (missing) *missing = absent;
  return v;
}

std::vector<double> signal_values_sorted(const SignalExpr& signal, const FlightData& data) {
  size_t missing = 0;
  const Eigen::VectorXd v = signal_sources_product(signal, data, &missing);
  std::vector<double> x;
  if (missing == signal.sources.size()) return x;
  for (Eigen::Index i = 0; i < v.size(); ++i)
    if (std::isfinite(v[i])) x.push_back(v[i]);
  if (x.size() < 20) return {};
  std::sort(x.begin(), x.end());
  return x;
}

SignalRange signal_range(const SignalExpr& signal, const FlightData& data) {
  const std::vector<double> x = signal_values_sorted(signal, data);
  if (x.empty()) return {};
  const auto at = [&](double q) {
    return x[static_cast<size_t>(q * static_cast<double>(x.size() - 1))];
  };
  const double lo = at(0.05), hi = at(0.95);
  return hi > lo ? SignalRange{lo, hi} : SignalRange{};
}

double signal_scale(const SignalExpr& signal, const FlightData& data) {
  const SignalRange r = signal_range(signal, data);
  return r.hi - r.lo;
}

bool in_signal_units(TransformKind kind) {
  return kind == TransformKind::Play || kind == TransformKind::Saturate ||
         kind == TransformKind::Step || kind == TransformKind::Ramp;
}

std::vector<double> parameter_grid(TransformKind kind, double dt_s, double span_s,
                                   double signal_scale, double signal_lo) {
  std::vector<double> g;
  auto geometric = [&](double lo, double hi, double factor) {
    for (double v = lo; v <= hi * (1 + 1e-9); v *= factor) g.push_back(v);
  };
  switch (kind) {
    case TransformKind::LowPass:
    case TransformKind::HighPass: {
      const double lo = std::max(2 * dt_s, 0.1);
      geometric(lo, std::min(3000.0, std::max(span_s / 3, 10 * lo)), 1.5);
      break;
    }
    case TransformKind::Decay:
      geometric(std::max(0.5 * dt_s, 0.02), 20.0, 1.4);
      break;
    case TransformKind::Delay: {
      const double step = std::max(dt_s, 0.05);
      for (double v = 0; v <= std::min(5.0, span_s / 10) + 1e-9; v += step) g.push_back(v);
      break;
    }
    case TransformKind::Power:
      for (double v = 0.5; v <= 4.0 + 1e-9; v += 0.25) g.push_back(v);
      break;
    case TransformKind::Play:
      if (signal_scale > 0) geometric(0.02 * signal_scale, 0.5 * signal_scale, 1.4);
      break;
    case TransformKind::Saturate: {
      const double m = std::max(std::abs(signal_lo), std::abs(signal_lo + signal_scale));
      if (signal_scale > 0 && m > 0) geometric(0.1 * m, 3.0 * m, 1.75);
      break;
    }
    case TransformKind::Step:
    case TransformKind::Ramp:
      if (signal_scale > 0)
        for (int k = 1; k <= 19; ++k) g.push_back(signal_lo + 0.05 * k * signal_scale);
      break;
    default:
      break;
  }
  return g;
}

double longest_scanned_time_constant_s(double dt_s, double span_s) {
  const std::vector<double> g = parameter_grid(TransformKind::LowPass, dt_s, span_s);
  return g.empty() ? 0.0 : g.back();
}

bool at_longest_scanned_time_constant(double tau_s, double top_s) {
  return top_s > 0 && tau_s >= 0.99 * top_s;
}

namespace {
double round3(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3g", v);
  return std::strtod(buf, nullptr);
}
bool logarithmic(TransformKind k) {
  return k == TransformKind::LowPass || k == TransformKind::HighPass || k == TransformKind::Decay;
}
// Golden-section search for a minimum of f between lo and hi: at most `iterations` steps, while
// the bracket is wider than tolerance x max(1, |hi|) (in f's argument). Returns the bracket's
// midpoint.
double golden_section(double lo, double hi, int iterations, double tolerance,
                      const std::function<double(double)>& f) {
  const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
  double x1 = hi - phi * (hi - lo), x2 = lo + phi * (hi - lo);
  double f1 = f(x1), f2 = f(x2);
  for (int it = 0; it < iterations && hi - lo > tolerance * std::max(1.0, std::abs(hi)); ++it) {
    if (f1 < f2) {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - phi * (hi - lo);
      f1 = f(x1);
    } else {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + phi * (hi - lo);
      f2 = f(x2);
    }
  }
  return 0.5 * (lo + hi);
}
}  // namespace

double scan_parameter(TransformKind kind, const std::vector<double>& grid,
                      const std::function<double(double)>& objective, double* best_out) {
  if (grid.empty()) throw Error("parameter scan: empty grid");
  size_t k = 0;
  double best = std::numeric_limits<double>::infinity();
  std::vector<double> f(grid.size());
  for (size_t i = 0; i < grid.size(); ++i) {
    f[i] = objective(grid[i]);
    if (f[i] < best) {
      best = f[i];
      k = i;
    }
  }
  double best_x = grid[k];
  if (grid.size() >= 2) {
    const bool lg = logarithmic(kind);
    auto to = [&](double v) { return lg ? std::log(v) : v; };
    auto from = [&](double u) { return lg ? std::exp(u) : u; };
    // A saturation level needs no more than 12 golden steps from its grid (a step's threshold
    // does: a switched load's error grows with every sample on the wrong side).
    const double x =
        from(golden_section(to(grid[k > 0 ? k - 1 : 0]), to(grid[std::min(k + 1, grid.size() - 1)]),
                            kind == TransformKind::Saturate ? 12 : 24, 1e-4,
                            [&](double u) { return objective(from(u)); }));
    const double r = round3(x);
    const double fr = objective(r);
    if (fr <= best) {
      best = fr;
      best_x = r;
    }
  }
  if (round3(best_x) != best_x) {  // a grid value: written with 3 significant digits too
    best_x = round3(best_x);
    best = objective(best_x);
  }
  if (best_out) *best_out = best;
  return best_x;
}

double scan_threshold(const std::vector<double>& sorted_values,
                      const std::function<double(double)>& objective, double* best_out) {
  if (sorted_values.empty()) throw Error("threshold scan: no value of the signal");
  const double last = static_cast<double>(sorted_values.size() - 1);
  const auto at = [&](double p) {  // the quantile at level p, interpolated between samples
    const double u = std::clamp(p, 0.0, 1.0) * last;
    const auto k = static_cast<size_t>(std::floor(u));
    const size_t k1 = std::min(k + 1, sorted_values.size() - 1);
    return sorted_values[k] + (u - static_cast<double>(k)) * (sorted_values[k1] - sorted_values[k]);
  };
  std::vector<double> levels = {0.02};
  for (int k = 1; k <= 19; ++k) levels.push_back(0.05 * k);
  levels.push_back(0.98);
  size_t k = 0;
  double best = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < levels.size(); ++i) {
    const double f = objective(at(levels[i]));
    if (f < best) {
      best = f;
      k = i;
    }
  }
  double best_x = at(levels[k]);
  // Down to a level of 1e-5: one sample in 100000 on the wrong side.
  const double level =
      golden_section(levels[k > 0 ? k - 1 : 0], levels[std::min(k + 1, levels.size() - 1)], 24,
                     1e-5, [&](double p) { return objective(at(p)); });
  const double fine = at(level);
  if (const double f = objective(fine); f <= best) {
    best = f;
    best_x = fine;
  }
  if (const double written = written_threshold(sorted_values, best_x); written != best_x) {
    best_x = written;
    best = objective(best_x);
  }
  if (best_out) *best_out = best;
  return best_x;
}

double written_threshold(const std::vector<double>& sorted_values, double x) {
  // Every threshold between the two samples around it splits the samples alike: written as the
  // middle of that gap with the fewest significant digits, three at least, that leave every
  // sample on the side of it it was on. A relay whose current dwells near its threshold moves a
  // share of its samples across a threshold rounded further (a 0.3074 A threshold written 0.307
  // flips 0.5 % of a flight's samples and doubles the error there).
  const auto below = [&](double t) {  // samples at or below t
    return std::upper_bound(sorted_values.begin(), sorted_values.end(), t) - sorted_values.begin();
  };
  const auto split = below(x);
  const auto n_values = static_cast<std::ptrdiff_t>(sorted_values.size());
  const double middle = split > 0 && split < n_values
                            ? 0.5 * (sorted_values[static_cast<size_t>(split - 1)] +
                                     sorted_values[static_cast<size_t>(split)])
                            : x;
  for (int digits = 3; digits <= 17; ++digits) {
    char buf[40];
    std::snprintf(buf, sizeof(buf), "%.*g", digits, middle);
    const double written = std::strtod(buf, nullptr);
    if (below(written) == split) return written;
  }
  return x;
}

namespace {

struct FreeRef {
  size_t term;     // index in model.terms
  size_t ordinal;  // index among that term's free parameters
  TransformKind kind;
};

double initial_guess(TransformKind k) {
  switch (k) {
    case TransformKind::LowPass:
    case TransformKind::HighPass:
      return 30.0;
    case TransformKind::Decay:
      return 0.5;
    case TransformKind::Delay:
      return 0.5;
    case TransformKind::Power:
      return 2.0;
    default:
      return 1.0;
  }
}

// The design of `model` on one flight, restricted to the columns its fit method can fit.
Eigen::MatrixXd fittable_design(const Model& model, const std::vector<TermPtr>& terms,
                                const FlightData& f) {
  const Eigen::MatrixXd a = design_matrix(model, terms, f);
  const std::vector<Eigen::Index> keep = fittable_columns(model.fit.method, terms);
  Eigen::MatrixXd kept(a.rows(), static_cast<Eigen::Index>(keep.size()));
  for (size_t k = 0; k < keep.size(); ++k) kept.col(static_cast<Eigen::Index>(k)) = a.col(keep[k]);
  return kept;
}

}  // namespace

std::vector<std::string> estimate_free_parameters(Model& model,
                                                  const std::vector<const FlightData*>& flights) {
  std::vector<FreeRef> refs;
  std::vector<std::shared_ptr<const ExprTerm>> free_terms(model.terms.size());
  for (size_t t = 0; t < model.terms.size(); ++t) {
    const ExprTerm* e = model.terms[t].expr();
    if (!e || !e->signal().has_free()) continue;
    size_t ord = 0;
    for (const auto& tr : e->signal().transforms) {
      if (tr.free) refs.push_back({t, ord++, tr.kind});
    }
    free_terms[t] = std::shared_ptr<const ExprTerm>(model.terms[t].shared(), e);
  }
  if (refs.empty()) return {};
  if (flights.empty()) throw Error("fit: no flight to estimate the free parameters on");
  std::vector<double> value(refs.size());
  for (size_t i = 0; i < refs.size(); ++i) value[i] = initial_guess(refs[i].kind);
  // The spec of term t with the current values (and `override` for parameter i).
  auto spec_of = [&](size_t t, long i = -1, double v = 0.0) {
    std::vector<double> vals;
    for (size_t j = 0; j < refs.size(); ++j) {
      if (refs[j].term == t) vals.push_back(static_cast<long>(j) == i ? v : value[j]);
    }
    return free_terms[t]->with_parameters(vals);
  };
  const FlightData& first = *flights[0];
  const double dt = first.dt_s();
  const double span = first.size() > 1 ? first.tt()[first.size() - 1] - first.tt()[0] : 1.0;
  std::vector<std::string> lines;
  const int sweeps = refs.size() > 1 ? 2 : 1;
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    for (size_t i = 0; i < refs.size(); ++i) {
      const size_t t = refs[i].term;
      Model base = model;
      base.terms.clear();
      for (size_t u = 0; u < model.terms.size(); ++u) {
        if (u == t) continue;
        base.terms.push_back(free_terms[u] ? spec_of(u) : model.terms[u].text());
      }
      base.coefficients.resize(0);
      const FitRowSet rows(base, flights, nullptr);
      if (rows.rows() == 0) {
        throw Error("fit: no usable fit sample to estimate '" + model.terms[t].text() + "'");
      }
      // The base's fittable columns, stacked.
      const auto base_terms = base.make_terms();
      std::vector<Eigen::MatrixXd> per_flight;
      std::vector<TermInputs> inputs;
      for (const FlightData* f : flights) {
        per_flight.push_back(fittable_design(base, base_terms, *f));
        inputs.push_back(make_term_inputs(*f, model.vector, model.bt_scale_nT));
      }
      const Eigen::MatrixXd base_rows = rows.stack(per_flight);
      const RidgeProfile profile(base_rows, rows.y(), model.fit.lambda);
      const double lag_s = base.scalar_lag_s();
      auto objective = [&](double v) {
        const auto term = make_term(spec_of(t, static_cast<long>(i), v));
        std::vector<Eigen::MatrixXd> cols;
        for (size_t f = 0; f < flights.size(); ++f) {
          Eigen::MatrixXd c(flights[f]->size(), term->columns());
          term->build(inputs[f], c);
          lag_round_trip(c, lag_s / flights[f]->dt_s());  // as design_matrix() builds it
          cols.push_back(std::move(c));
        }
        double rss = 0;
        profile.solve(rows.stack(cols), &rss);
        return std::isfinite(rss) ? rss : std::numeric_limits<double>::infinity();
      };
      const ExprTerm* expr = free_terms[t].get();
      if (refs[i].kind == TransformKind::Step) {
        const std::vector<double> values =
            expr && !flights.empty() ? signal_values_sorted(expr->signal(), *flights.front())
                                     : std::vector<double>{};
        if (values.empty() || !(values.back() > values.front()))
          throw Error("fit: '" + model.terms[t].text() +
                      "': no values of the signal to scan its threshold over");
        value[i] = scan_threshold(values, objective);
        if (sweep == sweeps - 1) {
          char buf[256];
          std::snprintf(buf, sizeof(buf),
                        "'%s': %s estimated %.3g (scanned its quantiles %.3g to %.3g)",
                        model.terms[t].text().c_str(),
                        Transform{refs[i].kind, 0.0, false}.param_meaning().c_str(), value[i],
                        values[values.size() / 50], values[values.size() - 1 - values.size() / 50]);
          lines.push_back(buf);
        }
        continue;
      }
      const SignalRange range = in_signal_units(refs[i].kind) && expr && !flights.empty()
                                    ? signal_range(expr->signal(), *flights.front())
                                    : SignalRange{};
      const std::vector<double> grid =
          parameter_grid(refs[i].kind, dt, span, range.hi - range.lo, range.lo);
      if (grid.empty())
        throw Error("fit: '" + model.terms[t].text() + "': no range of the signal to scan its " +
                    Transform{refs[i].kind, 0.0, true}.str() + " over");
      value[i] = scan_parameter(refs[i].kind, grid, objective);
      if (sweep == sweeps - 1) {
        char buf[256];
        std::snprintf(buf, sizeof(buf), "'%s': %s estimated %.3g (scanned %.3g to %.3g)",
                      model.terms[t].text().c_str(),
                      Transform{refs[i].kind, 0.0, false}.param_meaning().c_str(), value[i],
                      grid.front(), grid.back());
        lines.push_back(buf);
      }
    }
  }
  for (size_t t = 0; t < model.terms.size(); ++t) {
    if (free_terms[t]) model.terms[t] = spec_of(t);
  }
  return lines;
}

}  // namespace magcomp
