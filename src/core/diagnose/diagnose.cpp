// magcomp: diagnose: the nested split, the base refit, the search over the term language, the
// verdict.
#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/fit/model_fit.h"

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
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/fit/slow_stage.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {
namespace {

const std::set<std::string> kBookkeeping = {"tt", "line", "flight", "year", "doy", "N", "dt"};

bool is_current(const std::string& n) { return n.rfind("cur_", 0) == 0; }
bool is_rate(const std::string& n) {
  return n.size() > 5 && n.compare(n.size() - 5, 5, "_rate") == 0;
}

// The shorthand a plain source is written with: current:X, rate:X, or field:X.
std::string plain_spec(const std::string& x) {
  if (is_electrical(x)) return "current:" + x;
  if (is_rate(x)) return "rate:" + x;
  return "field:" + x;
}

std::string family_of_tl(const std::string& spec) {
  for (const char* f : {"permanent", "induced", "eddy"}) {
    if (spec.rfind(f, 0) == 0 && spec.find(':') == std::string::npos) return f;
  }
  return spec;
}

// One term to try: its spec (free parameters as ?), what kind of effect, which channel.
struct Job {
  std::string spec;
  std::string family;
  std::string channel;
};

// Result of one job.
struct Scored {
  bool ok = false;
  std::string spec;  // parameters as numbers
  double sel = 0, conf = 0, held = 0;
  Eigen::VectorXd coef;  // the candidate's coefficients
  long fits = 0;
  std::string note;
  bool slow = false;  // fitted by the slow stage (Model::slow_terms), not the band-pass
};

// A column whose band-passed energy on the calibration segments is below this share of its
// energy there (segment means removed) is one the band-pass barely sees: it is also fitted by
// the slow stage, and the better of the two on the selection lines is kept.
constexpr double kSlowBandFraction = 0.01;

// Mean-removed RMS per line over the rows of one fold (-1: every held-out row); NaN when fewer
// than 90 % of the fold's rows have a finite error (a score must stand on the baseline's rows:
// a lag loses a few at the ends, a NaN coefficient loses them all).
double fold_std(const Eigen::VectorXd& e, const std::vector<Eigen::Index>& held,
                const std::vector<int>& fold, const Eigen::VectorXd& line, int which) {
  std::map<double, std::pair<double, double>> acc;
  double rows = 0;
  for (Eigen::Index i : held) {
    if (which >= 0 && fold[static_cast<size_t>(i)] != which) continue;
    rows += 1;
    if (!std::isfinite(e[i])) continue;
    auto& a = acc[line[i]];
    a.first += e[i];
    a.second += 1;
  }
  double ss = 0, n = 0;
  for (Eigen::Index i : held) {
    if (which >= 0 && fold[static_cast<size_t>(i)] != which) continue;
    if (!std::isfinite(e[i])) continue;
    const auto& a = acc[line[i]];
    const double d = e[i] - a.first / a.second;
    ss += d * d;
    n += 1;
  }
  return n > 1 && n >= 0.9 * rows ? std::sqrt(ss / n) : NAN;
}

// Everything a candidate is scored against: read-only once built, shared by the workers.
class Search {
 public:
  Search(const Model& model, const FlightData& data, const std::string& truth_name, Diagnosis* dx);

  // Scores a term's columns (N x k): fit on the fit rows with the base columns, errors on the
  // held-out rows of each fold. With `slow_ok`, a column the band-pass barely sees
  // (kSlowBandFraction) is also scored by the slow stage; the better on the selection lines is
  // returned.
  Scored score(const Eigen::MatrixXd& cols, bool slow_ok = false) const;
  // Scores columns fitted by the slow stage: to the base error on the calibration rows,
  // unfiltered, each segment's mean removed.
  Scored score_slow(const Eigen::MatrixXd& cols) const;
  // The slow stage's residual sum of squares with these columns (nT²).
  double slow_rss(const Eigen::MatrixXd& cols) const;
  // Whether the slow stage exists here: a band-pass fit on this flight's calibration segments.
  bool has_slow_stage() const { return slow_stage != nullptr; }
  // The fit's residual sum of squares with these columns added.
  double fit_rss(const Eigen::MatrixXd& cols) const;
  // Builds, scans (free parameters) and scores one job.
  Scored run(const Job& job) const;
  // The lag scan, alone or with partner columns (N x k, built without a lag: columns_of(spec,
  // false)): each trial realigns the scalar by tau and gives every column tau's round trip.
  Scored lag_candidate(double* tau_out, const Eigen::MatrixXd& partner) const;
  // The lag fixed at tau (s), with partner columns (built without a lag).
  Scored lag_at(double tau, const Eigen::MatrixXd& partner) const;
  // The columns of a term on this flight, N x k; with `with_lag`, carrying the model's lag
  // round trip as the base columns do (design_matrix).
  Eigen::MatrixXd columns_of(const Term& t, bool with_lag = true) const {
    Eigen::MatrixXd c(data.size(), t.columns());
    t.build(inputs, c);
    if (with_lag) lag_round_trip(c, model.scalar_lag_s() / dt);
    return c;
  }
  Eigen::MatrixXd columns_of(const std::string& spec, bool with_lag = true) const {
    return columns_of(*make_term(spec), with_lag);
  }

  const Model& model;
  const FlightData& data;
  Eigen::VectorXd scalar, truth, line;
  FitSettings fs;
  std::vector<std::pair<Eigen::Index, Eigen::Index>> runs;
  std::vector<Eigen::Index> held;
  std::vector<int> fold;  // per sample: 0 selection, 1 confirmation, -1 not held out
  std::vector<int> unit;  // per sample: its held-out unit, in time order (-1: not held out)
  TermInputs inputs;
  Eigen::MatrixXd a0;  // the base's fittable columns, N x p
  Eigen::MatrixXd af0;
  Eigen::VectorXd yf;
  std::unique_ptr<RidgeProfile> profile;
  Eigen::VectorXd e0;                     // base error, N
  Eigen::VectorXd slow0;                  // the base's slow-stage correction (Model::slow_terms), N
  std::unique_ptr<SlowStage> slow_stage;  // a candidate's slow fit (band-pass models only)
  double base_std[3] = {0, 0, 0};         // selection, confirmation, all held out
  double dt = 0.1, span = 1.0;

 private:
  Eigen::MatrixXd stacked(const Eigen::MatrixXd& cols) const {
    const Eigen::MatrixXd z = cols.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
    return stack_runs(fs, dt, z, runs);
  }
  // stacked() of the columns given a lag's round trip of tau s (only the fit rows are built).
  Eigen::MatrixXd stacked_at_lag(const Eigen::MatrixXd& cols, double tau) const;
  // The base's fittable columns without the model's lag round trip, then `partner`: N x (p + k).
  Eigen::MatrixXd lag_columns(const Eigen::MatrixXd& partner) const;
  // The fit of lag_columns() `x` with a lag of tau s: the stacked fit rows' residual sum of
  // squares, and the coefficients in `coef`.
  double lag_fit(double tau, const Eigen::MatrixXd& x, Eigen::VectorXd* coef) const;
  // lag_at() with lag_columns() `x` of which the last `partners` are the partner's.
  Scored lag_scored(double tau, Eigen::MatrixXd x, Eigen::Index partners) const;
};

Search::Search(const Model& m, const FlightData& d, const std::string& truth_name, Diagnosis* dx)
    : model(m), data(d) {
  require_model_fields_in_range(model, data, {truth_name});
  truth = data.column(truth_name);
  const auto terms = model.make_terms();
  const Eigen::MatrixXd a_all = design_matrix(model, terms, data);  // names a missing field
  scalar = aligned_scalar(model, data);
  line =
      data.has("line") ? Eigen::VectorXd(data.column("line")) : Eigen::VectorXd::Zero(data.size());
  const Eigen::Index n = data.size();
  dt = data.dt_s();
  span = n > 1 ? data.tt()[n - 1] - data.tt()[0] : 1.0;
  // --- Fit rows: the model's own calibration when this flight holds it.
  fs = model.fit;
  Eigen::VectorXd y;
  bool own = false;
  if (!(fs.lines.empty() && fs.windows.empty())) {
    if (fs.method == FitMethod::kReference && !data.has(fs.reference)) {
      throw Error(data.source() + ": field '" + fs.reference + "' (fit.reference) not found");
    }
    y = fs.method == FitMethod::kBandpass ? scalar
                                          : Eigen::VectorXd(scalar - data.column(fs.reference));
    runs = calibration_runs(fs, data, a_all, y, nullptr);
    own = !runs.empty();
  }
  std::vector<bool> in_fit(static_cast<size_t>(n), false);
  if (own) {
    for (Eigen::Index i : data.select(fs.lines, fs.windows)) in_fit[static_cast<size_t>(i)] = true;
    dx->split = fs.method == FitMethod::kBandpass
                    ? "fit on the model's calibration segments (band-pass)"
                    : "fit on the model's fit lines (reference " + fs.reference + ")";
  } else {
    std::vector<double> lines;
    for (Eigen::Index i = 0; i < n; ++i) {
      if (std::isfinite(line[i]) && std::find(lines.begin(), lines.end(), line[i]) == lines.end())
        lines.push_back(line[i]);
    }
    std::sort(lines.begin(), lines.end());
    if (lines.size() < 3) {
      throw Error(data.source() +
                  ": diagnose needs three lines, or the model's calibration segments and two more");
    }
    fs.method = FitMethod::kReference;
    fs.reference = truth_name;
    fs.windows.clear();
    fs.lines.clear();
    for (size_t k = 0; k < lines.size(); k += 2) fs.lines.push_back(lines[k]);
    y = scalar - truth;
    runs = calibration_runs(fs, data, a_all, y, nullptr);
    for (Eigen::Index i : data.select(fs.lines, {})) in_fit[static_cast<size_t>(i)] = true;
    dx->split = "fit: reference fit against " + truth_name + " on every other line";
  }
  if (runs.empty()) throw Error(data.source() + ": no usable fit samples for diagnose");
  // --- The base: the model's fittable columns, refitted.
  const std::vector<Eigen::Index> keep = fittable_columns(fs.method, terms, model.slow_terms);
  a0.resize(n, static_cast<Eigen::Index>(keep.size()));
  for (size_t k = 0; k < keep.size(); ++k)
    a0.col(static_cast<Eigen::Index>(k)) = a_all.col(keep[k]);
  af0 = stack_runs(fs, dt, a0, runs);
  yf = stack_runs(fs, dt, y, runs).col(0);
  dx->fit_samples = yf.size();
  profile = std::make_unique<RidgeProfile>(af0, yf, fs.lambda);
  const Eigen::VectorXd c0 = profile->solve(Eigen::MatrixXd(yf.size(), 0), nullptr);
  e0 = scalar - truth - a0 * c0;
  // --- The base's slow terms, fitted after the band-pass stage as fit_model does.
  slow0 = Eigen::VectorXd::Zero(n);
  if (fs.method == FitMethod::kBandpass) {
    const std::vector<Eigen::Index> slow = slow_columns(fs.method, terms, model.slow_terms);
    Eigen::MatrixXd sc(n, static_cast<Eigen::Index>(slow.size()));
    for (size_t k = 0; k < slow.size(); ++k)
      sc.col(static_cast<Eigen::Index>(k)) = a_all.col(slow[k]);
    // A candidate's slow fit: with the base's band-pass and slow columns' span removed.
    if (slow.empty()) {
      slow_stage = std::make_unique<SlowStage>(a0, e0, runs, fs.lambda);
    } else {
      const Eigen::VectorXd cs = SlowStage(a0, e0, runs, fs.lambda).fit(sc);
      slow0 = sc.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; }) * cs;
      e0 -= slow0;
      Eigen::MatrixXd nuisance(n, a0.cols() + sc.cols());
      nuisance << a0, sc;
      slow_stage = std::make_unique<SlowStage>(nuisance, e0, runs, fs.lambda);
    }
  }
  // --- Held out: every other line, in units (a line, or each contiguous piece of a line flown in
  // pieces) dealt in time order into selection and confirmation.
  unit.assign(static_cast<size_t>(n), -1);
  int units = 0;
  Eigen::Index prev = -2;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (in_fit[static_cast<size_t>(i)] || !std::isfinite(e0[i]) || !std::isfinite(line[i]))
      continue;
    if (prev != i - 1 || line[i] != line[prev]) ++units;
    unit[static_cast<size_t>(i)] = units - 1;
    held.push_back(i);
    prev = i;
  }
  if (held.size() < 100) throw Error(data.source() + ": too few held-out samples for diagnose");
  fold.assign(static_cast<size_t>(n), -1);
  if (units >= 2) {
    for (Eigen::Index i : held) fold[static_cast<size_t>(i)] = unit[static_cast<size_t>(i)] % 2;
  } else {  // one held-out piece: its first and second halves
    for (size_t k = 0; k < held.size(); ++k) {
      fold[static_cast<size_t>(held[k])] = k < held.size() / 2 ? 0 : 1;
      unit[static_cast<size_t>(held[k])] = k < held.size() / 2 ? 0 : 1;
    }
  }
  for (Eigen::Index i : held) {
    auto& v = fold[static_cast<size_t>(i)] == 0 ? dx->selection_lines : dx->confirmation_lines;
    if (std::find(v.begin(), v.end(), line[i]) == v.end()) v.push_back(line[i]);
  }
  dx->split +=
      "; held out: the other lines, ranked on the selection lines and confirmed on the "
      "confirmation lines (alternate lines, or pieces of a line, in time order)";
  dx->heldout_samples = static_cast<Eigen::Index>(held.size());
  for (int f = 0; f < 2; ++f) base_std[f] = fold_std(e0, held, fold, line, f);
  base_std[2] = fold_std(e0, held, fold, line, -1);
  for (double s : base_std)
    if (!(s > 0 && s <= kMaxField_nT)) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.3g", s);
      throw Error(data.source() + ": the held-out error of " + model.scalar + " against " +
                  truth_name + " has a std of " + buf +
                  " nT on a split (it must be above 0 and within 1e6 nT, the range of any "
                  "magnetic field): nothing to diagnose");
    }
  dx->baseline_selection_std_nT = base_std[0];
  dx->baseline_confirmation_std_nT = base_std[1];
  dx->baseline_std_nT = base_std[2];
  inputs = make_term_inputs(data, model.vector, model.bt_scale_nT);
}

double Search::fit_rss(const Eigen::MatrixXd& cols) const {
  double rss = 0;
  profile->solve(stacked(cols), &rss);
  return std::isfinite(rss) ? rss : std::numeric_limits<double>::infinity();
}

double Search::slow_rss(const Eigen::MatrixXd& cols) const {
  double rss = 0;
  slow_stage->fit(cols, &rss);
  return std::isfinite(rss) ? rss : std::numeric_limits<double>::infinity();
}

Scored Search::score_slow(const Eigen::MatrixXd& cols) const {
  Scored s;
  const Eigen::VectorXd coef = slow_stage->fit(cols);
  Eigen::VectorXd e = Eigen::VectorXd::Constant(data.size(), NAN);
  for (Eigen::Index i : held) {
    double v = e0[i];
    for (Eigen::Index j = 0; j < cols.cols(); ++j) {
      if (std::isfinite(cols(i, j))) v -= cols(i, j) * coef[j];
    }
    e[i] = v;
  }
  s.sel = fold_std(e, held, fold, line, 0);
  s.conf = fold_std(e, held, fold, line, 1);
  s.held = fold_std(e, held, fold, line, -1);
  s.coef = coef;
  s.slow = true;
  s.ok = std::isfinite(s.sel) && std::isfinite(s.conf) && std::isfinite(s.held) && coef.allFinite();
  return s;
}

Scored Search::score(const Eigen::MatrixXd& cols, bool slow_ok) const {
  Scored s;
  const Eigen::MatrixXd band = stacked(cols);
  const Eigen::VectorXd coef = profile->solve(band, nullptr);
  const Eigen::Index p = a0.cols(), k = cols.cols();
  Eigen::VectorXd e = Eigen::VectorXd::Constant(data.size(), NAN);
  for (Eigen::Index i : held) {
    double v = scalar[i] - truth[i] - a0.row(i).dot(coef.head(p));
    for (Eigen::Index j = 0; j < k; ++j) {
      if (std::isfinite(cols(i, j))) v -= cols(i, j) * coef[p + j];  // no data: no correction
    }
    e[i] = v;
  }
  s.sel = fold_std(e, held, fold, line, 0);
  s.conf = fold_std(e, held, fold, line, 1);
  s.held = fold_std(e, held, fold, line, -1);
  s.coef = coef.tail(k);
  s.ok = std::isfinite(s.sel) && std::isfinite(s.conf) && std::isfinite(s.held) && coef.allFinite();
  if (slow_ok && has_slow_stage() && k > 0) {
    // The columns' energy on the calibration rows, each segment's mean removed.
    double raw = 0;
    for (const auto& [first, last] : runs) {
      const auto block = cols.middleRows(first, last - first + 1);
      const Eigen::RowVectorXd mean =
          block.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; }).colwise().mean();
      raw += (block.rowwise() - mean)
                 .unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; })
                 .squaredNorm();
    }
    if (band.squaredNorm() < kSlowBandFraction * raw) {
      Scored slow = score_slow(cols);
      if (slow.ok && (!s.ok || slow.sel < s.sel)) return slow;
    }
  }
  return s;
}

Scored Search::run(const Job& job) const {
  auto term = make_term(job.spec);
  auto columns = [&](const Term& t) { return columns_of(t); };
  long fits = 0;
  const auto* expr = dynamic_cast<const ExprTerm*>(term.get());
  // The slow stage sizes what heats or drifts with a current or a voltage; a slow fit of
  // position, attitude or the field itself against the reference is where map and trajectory
  // leakage would hide.
  bool slow_ok = expr && has_slow_stage() && !expr->signal().sources.empty();
  if (expr) {
    for (const auto& src : expr->signal().sources) slow_ok = slow_ok && is_electrical(src);
  }
  if (expr && expr->signal().has_free()) {
    TransformKind kind = TransformKind::LowPass;
    for (const auto& tr : expr->signal().transforms)
      if (tr.free) kind = tr.kind;
    const SignalRange range =
        in_signal_units(kind) ? signal_range(expr->signal(), data) : SignalRange{};
    std::vector<double> grid = parameter_grid(kind, dt, span, range.hi - range.lo, range.lo);
    if (grid.empty()) return Scored{};
    if (kind == TransformKind::Delay) {  // delays up to 2 s at the grid's step: a periodic
      grid.erase(std::remove_if(grid.begin(), grid.end(), [](double v) { return v > 2.0 + 1e-9; }),
                 grid.end());       // source (a strobe) makes the objective many-valleyed
    } else if (grid.size() > 12) {  // a coarser grid; the golden section refines it
      std::vector<double> thin;
      for (size_t k = 0; k < grid.size(); k += (grid.size() + 11) / 12) thin.push_back(grid[k]);
      grid = thin;
    }
    // A low-pass or a decay may be slower than the band-pass sees: on its grid the slow stage's
    // fit is scored too, and refined where it explains more than the band-pass choice.
    const bool scan_slow =
        slow_ok && (kind == TransformKind::LowPass || kind == TransformKind::Decay);
    std::vector<double> slow_f;
    double v = scan_parameter(kind, grid, [&](double x) {
      ++fits;
      const Eigen::MatrixXd c = columns(*make_term(expr->with_parameters({x})));
      if (scan_slow && slow_f.size() < grid.size()) slow_f.push_back(slow_rss(c));
      return fit_rss(c);
    });
    if (scan_slow && slow_f.size() == grid.size()) {
      const size_t k =
          static_cast<size_t>(std::min_element(slow_f.begin(), slow_f.end()) - slow_f.begin());
      if (slow_f[k] < 0.98 * slow_stage->base_rss()) {
        const std::vector<double> near = {grid[k > 0 ? k - 1 : 0], grid[k],
                                          grid[std::min(k + 1, grid.size() - 1)]};
        const double vs = scan_parameter(kind, near, [&](double x) {
          ++fits;
          return slow_rss(columns(*make_term(expr->with_parameters({x}))));
        });
        auto slow_term = make_term(expr->with_parameters({vs}));
        Scored ss = score_slow(columns(*slow_term));
        ss.spec = slow_term->spec();
        auto band_term = make_term(expr->with_parameters({v}));
        const Eigen::MatrixXd band_cols = columns(*band_term);
        Scored sb = score(band_cols, true);
        sb.spec = band_term->spec();
        if (!(band_cols.array().isFinite().any())) sb.ok = false;
        Scored& best = ss.ok && (!sb.ok || ss.sel < sb.sel) ? ss : sb;
        best.fits = fits + 2;
        return best;
      }
    }
    if (kind == TransformKind::Delay && v < 0.5 * dt) {  // no delay: the plain form says it
      Scored none;
      none.fits = fits;
      return none;
    }
    term = make_term(expr->with_parameters({v}));
  }
  const Eigen::MatrixXd cols = columns(*term);
  Scored s = score(cols, slow_ok);
  s.spec = term->spec();
  s.fits = fits + 1;
  if (!(cols.array().isFinite().any())) s.ok = false;
  return s;
}

Eigen::MatrixXd Search::stacked_at_lag(const Eigen::MatrixXd& cols, double tau) const {
  const double lag_samples = tau / dt;
  const Eigen::Index reach = lag_round_trip_slice_margin(lag_samples), n = data.size();
  // Each run with `reach` rows each side: its rows get the same numbers as on the whole flight
  // (with fewer, a fractional lag of more than a sample gives the last rows of each run the
  // slice's held end, and the band-pass spreads that back over the run), and the rest of the
  // flight is never copied.
  Eigen::Index rows = 0;
  for (const auto& [first, last] : runs)
    rows += std::min(n - 1, last + reach) - std::max<Eigen::Index>(0, first - reach) + 1;
  Eigen::MatrixXd part(rows, cols.cols());
  std::vector<std::pair<Eigen::Index, Eigen::Index>> local;
  Eigen::Index r = 0;
  for (const auto& [first, last] : runs) {
    const Eigen::Index lo = std::max<Eigen::Index>(0, first - reach);
    const Eigen::Index len = std::min(n - 1, last + reach) - lo + 1;
    part.middleRows(r, len) = cols.middleRows(lo, len);
    lag_round_trip(part.middleRows(r, len), lag_samples);
    local.emplace_back(r + first - lo, r + last - lo);
    r += len;
  }
  part = part.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
  return stack_runs(fs, dt, part, local);
}

Eigen::MatrixXd Search::lag_columns(const Eigen::MatrixXd& partner) const {
  Model m = model;
  m.terms.erase(std::remove_if(m.terms.begin(), m.terms.end(),
                               [](const std::string& t) { return t.rfind("lag:", 0) == 0; }),
                m.terms.end());
  const auto terms = m.make_terms();
  const std::vector<Eigen::Index> keep = fittable_columns(fs.method, terms, model.slow_terms);
  const Eigen::Index p = static_cast<Eigen::Index>(keep.size());
  Eigen::MatrixXd x(data.size(), p + partner.cols());
  {
    const Eigen::MatrixXd a_all = design_matrix(m, terms, data);
    for (Eigen::Index k = 0; k < p; ++k) x.col(k) = a_all.col(keep[static_cast<size_t>(k)]);
  }
  x.rightCols(partner.cols()) = partner;
  return x;
}

double Search::lag_fit(double tau, const Eigen::MatrixXd& x, Eigen::VectorXd* coef) const {
  const Eigen::MatrixXd xf = stacked_at_lag(x, tau);
  const Eigen::MatrixXd g = xf.transpose() * xf;
  Eigen::MatrixXd r = g;
  r.diagonal().array() +=
      fs.lambda + 1e-12 * std::max(g.trace() / std::max<double>(g.cols(), 1), 1e-300);
  const FlightData::Column raw = data.column(model.scalar);
  const Eigen::VectorXd s_held = shift_samples(raw, -tau / dt, true);  // filters need no NaN
  const Eigen::VectorXd yl = fs.method == FitMethod::kBandpass
                                 ? s_held
                                 : Eigen::VectorXd(s_held - data.column(fs.reference));
  const Eigen::VectorXd ylf = stack_runs(fs, dt, yl, runs).col(0);
  *coef = r.ldlt().solve(xf.transpose() * ylf);
  return (ylf - xf * *coef).squaredNorm();
}

Scored Search::lag_candidate(double* tau_out, const Eigen::MatrixXd& partner) const {
  // Each trial realigns the raw scalar by tau (absolute) and gives the columns tau's round trip,
  // as a model with lag:tau does. Coarse grid over the model's lag +-1 s, then golden-section
  // refinement to 1 ms. A model that has a lag gets it re-estimated. With partner columns
  // (N x k) the lag is scanned and scored together with them: a lag moves the signature of every
  // effect, so it is judged with the term whose timing it explains.
  const double current = model.scalar_lag_s();
  Eigen::MatrixXd x = lag_columns(partner);
  // Estimated on the fit rows, as every free parameter is: the calibration maneuvers hold the
  // field rates that reveal a lag; the held-out lines (straight and level) barely do.
  Eigen::VectorXd coef;
  auto cost = [&](double tau) { return lag_fit(tau, x, &coef); };
  std::vector<double> grid;
  for (double tau = current - 1.0; tau <= current + 1.0 + 1e-9; tau += 0.05) grid.push_back(tau);
  // To the millisecond: at the field rates of a maneuver (tens of nT/s) 5 ms of lag error is
  // a fraction of a nT on the next flight.
  const double tau = std::round(scan_parameter(TransformKind::Delay, grid, cost) * 1000) / 1000;
  Scored s = lag_scored(tau, std::move(x), partner.cols());
  s.fits = static_cast<long>(grid.size()) + 26;
  *tau_out = tau;
  return s;
}

Scored Search::lag_at(double tau, const Eigen::MatrixXd& partner) const {
  return lag_scored(tau, lag_columns(partner), partner.cols());
}

Scored Search::lag_scored(double tau, Eigen::MatrixXd x, Eigen::Index partners) const {
  Eigen::VectorXd c;
  lag_fit(tau, x, &c);
  lag_round_trip(x, tau / dt);
  const Eigen::Index p = x.cols() - partners;
  // NaN past the ends; a partner without data gives no correction.
  Eigen::VectorXd e = shift_samples(data.column(model.scalar), -tau / dt) - truth -
                      x.leftCols(p) * c.head(p) - slow0;
  if (partners > 0) {
    e -= x.rightCols(partners).unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; }) *
         c.tail(partners);
  }
  Scored s;
  s.spec = "lag";
  s.sel = fold_std(e, held, fold, line, 0);
  s.conf = fold_std(e, held, fold, line, 1);
  s.held = fold_std(e, held, fold, line, -1);
  s.ok = std::abs(tau - model.scalar_lag_s()) >= 0.005 && std::isfinite(s.sel) &&
         std::isfinite(s.conf) && std::isfinite(s.held) && c.allFinite();
  s.fits = 1;
  return s;
}

// Candidate jobs for the sources and the model.
std::vector<Job> make_jobs(const Model& model, const std::vector<std::string>& sources) {
  std::vector<Job> jobs;
  std::set<std::string> have(model.terms.begin(), model.terms.end());
  std::set<std::string> shapes;  // a term of the model is re-estimated with ?, not searched again
  for (const auto& t : model.terms) {
    if (const auto e = parse_expr_term(t)) shapes.insert(e->shape());
  }
  std::set<std::string> families;
  for (const auto& t : model.terms) families.insert(family_of_tl(t));
  auto add = [&](const std::string& spec, const std::string& family, const std::string& ch) {
    if (have.count(spec)) return;
    if (const auto e = parse_expr_term(spec); e && shapes.count(e->shape())) return;
    jobs.push_back({spec, family, ch});
  };
  for (const char* f : {"permanent", "induced", "eddy"}) {
    if (!families.count(f)) add(f, "tolles-lawson", "");
  }
  add("second_order", "second order", "");
  add("field:B|decay(?)", "eddy currents that decay", "");
  add("scalar:Bt", "induced field scaling with |B|", "");
  add("scalar:" + model.scalar + "|d", "scalar sensor response", model.scalar);
  for (const std::string& x : sources) {
    add(plain_spec(x), is_rate(x) ? "attitude rate" : "field of a channel", x);
    add(is_electrical(x) ? "dcurrent:" + x : "field:" + x + "|d", "rate of change", x);
    add("field:" + x + "|lp(?)", "slow response (thermal)", x);
    add("field:" + x + "|delay(?)", "delayed response", x);
    add("scalar:" + x + "|lp(?)", "drift of the reading", x);
    if (is_current(x)) {
      add("field:" + x + "|pow(2)|lp(?)", "heating (I²) response", x);
      add("field:" + x + "|int", "state (integral of a current)", x);
      add("field:" + x + "|play(?)", "hysteresis (magnetised by the current, with play)", x);
      add("field:" + x + "|sat(?)", "a saturating core (the field levels off with the current)", x);
      add("field:" + x + "|step(?)", "a switched load (on above a level of the current)", x);
    }
  }
  return jobs;
}

// Runs jobs on `threads` workers.
std::vector<Scored> run_jobs(const Search& search, const std::vector<Job>& jobs, int threads) {
  std::vector<Scored> out(jobs.size());
  std::atomic<size_t> next{0};
  auto worker = [&] {
    for (size_t k; (k = next++) < jobs.size();) {
      try {
        out[k] = search.run(jobs[k]);
      } catch (const std::exception& e) {
        out[k].ok = false;
        out[k].note = "candidate '" + jobs[k].spec + "' skipped: " + e.what();
      }
    }
  };
  std::vector<std::future<void>> pool;
  for (int t = 1; t < std::max(threads, 1); ++t)
    pool.push_back(std::async(std::launch::async, worker));
  worker();
  for (auto& f : pool) f.get();
  return out;
}

double share(double after, double before) {
  return before > 0 ? 1.0 - (after / before) * (after / before) : 0.0;
}

}  // namespace

bool is_electrical(const std::string& channel) {
  return channel.rfind("cur_", 0) == 0 || channel.rfind("vol_", 0) == 0;
}

// How much a term says: its sources and transforms (a shorthand or TL family counts 1).
int term_complexity(const std::string& spec) {
  const auto e = parse_expr_term(spec);
  if (!e) return 1;
  int n = static_cast<int>(e->signal().sources.size() + e->signal().transforms.size());
  for (const auto& t : e->signal().transforms) n += t.has_param();
  return n;
}

std::vector<std::string> source_fields(const Model& model, const FlightData& data,
                                       const std::string& truth, bool full_search,
                                       std::vector<std::string>* notes) {
  std::vector<std::string> out;
  for (const std::string& name : data.names()) {
    if (kBookkeeping.count(name) || name.rfind("mag_", 0) == 0 || name.rfind("flux_", 0) == 0 ||
        name == truth || name == model.fit.reference || name == "diurnal" ||
        name.rfind("ogs_", 0) == 0 || name == "drape" || name.front() == '~') {
      continue;
    }
    if (!full_search && !is_electrical(name) && !is_rate(name)) continue;
    const FlightData::Column x = data.column(name);
    double lo = INFINITY, hi = -INFINITY;
    Eigen::Index finite = 0;
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      if (std::isfinite(x[i])) {
        lo = std::min(lo, x[i]);
        hi = std::max(hi, x[i]);
        ++finite;
      }
    }
    if (!(hi > lo)) {
      if (notes) notes->push_back("channel '" + name + "' is constant (or all NaN); skipped");
      continue;
    }
    if (finite < x.size() * 9 / 10) {
      if (notes) notes->push_back("channel '" + name + "' is more than 10 % NaN; skipped");
      continue;
    }
    out.push_back(name);
  }
  return out;
}

namespace {

// The model to diagnose: the reference checked, and a template's free parameters estimated.
Model prepared_model(const Model& model_in, const FlightData& data, const std::string& truth_name) {
  if (!data.has(truth_name)) {
    throw Error(data.source() + ": reference field '" + truth_name + "' not found");
  }
  if (!data.column(truth_name).array().isFinite().any()) {
    throw Error(data.source() + ": reference field '" + truth_name + "' holds no finite sample");
  }
  Model model = model_in;
  for (const auto& t : model.terms) {
    if (t.find('?') != std::string::npos) {
      fit_model(model, {&data});
      break;
    }
  }
  return model;
}

// Products of the strongest sources (their best single form explains more than
// accept_fraction on the selection lines): at most 4 sources, so 6 products.
std::vector<Job> product_jobs(const Model& model, const Search& search,
                              const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                              double accept_fraction) {
  std::map<std::string, double> best_by_source;
  for (size_t k = 0; k < jobs.size(); ++k) {
    if (!scored[k].ok || jobs[k].channel.empty() || jobs[k].channel == model.scalar) continue;
    auto& b = best_by_source[jobs[k].channel];
    b = std::max(b, share(scored[k].sel, search.base_std[0]));
  }
  std::vector<std::pair<double, std::string>> strongest;
  for (const auto& [ch, v] : best_by_source) {
    if (v > accept_fraction) strongest.emplace_back(v, ch);
  }
  std::sort(strongest.rbegin(), strongest.rend());
  if (strongest.size() > 4) strongest.resize(4);
  std::vector<Job> products;
  for (size_t a = 0; a < strongest.size(); ++a) {
    for (size_t b = a + 1; b < strongest.size(); ++b) {
      const std::string& x = strongest[a].second;
      const std::string& y = strongest[b].second;
      products.push_back({"field:" + x + "*" + y, "product of two channels", x + "*" + y});
    }
  }
  return products;
}

// The grammar search: the best-scoring electrical channel terms so far grow by one transform each,
// a dynamic one after the chain (lp(?), d, sat(?)) or a static law before it (pow(2), abs), within
// a budget of kMaxChain transforms; the parameters estimated so far stay as numbers, so each child
// has at most one '?'. kRefineParents parents per level, two levels: best-first.
constexpr size_t kRefineParents = 4;
constexpr size_t kMaxChain = 3;

// True when a time constant of the term sits at the top of its scan: the flight cannot tell it
// from a slower one, so it stands for a drift, not an estimated response. Neither grown from nor
// kept as a grown chain.
bool at_slow_edge(const std::string& spec, const Search& search) {
  const auto e = parse_expr_term(spec);
  if (!e) return false;
  for (const auto& t : e->signal().transforms) {
    if (t.kind != TransformKind::LowPass && t.kind != TransformKind::HighPass) continue;
    const std::vector<double> g = parameter_grid(t.kind, search.dt, search.span);
    if (!g.empty() && t.param >= 0.99 * g.back()) return true;
  }
  return false;
}

std::vector<Job> refined_jobs(const Model& model, const Search& search,
                              const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                              std::set<std::string>* seen) {
  std::vector<std::pair<double, size_t>> order;
  for (size_t k = 0; k < jobs.size(); ++k) {
    // Chains are the laws of electrical loads (heating, saturation, switching): grown from
    // terms of currents and voltages only (and their products). An attitude or velocity grown
    // into |x| through a slow low-pass becomes a proxy of when the aircraft turned.
    if (!scored[k].ok || jobs[k].channel.empty() || jobs[k].channel == model.scalar ||
        !is_electrical(jobs[k].channel.substr(0, jobs[k].channel.find('*'))))
      continue;
    // Grown from the terms that explain most on both folds (the smaller share), so a term
    // that only fits the selection lines does not take the budget.
    order.emplace_back(-std::min(share(scored[k].sel, search.base_std[0]),
                                 share(scored[k].conf, search.base_std[1])),
                       k);
  }
  std::sort(order.begin(), order.end());
  std::set<std::string> shapes;  // a model term's shape is re-estimated, not grown
  for (const auto& t : model.terms)
    if (const auto e = parse_expr_term(t)) shapes.insert(e->shape());
  std::vector<Job> out;
  size_t parents = 0;
  for (const auto& entry : order) {
    const size_t k = entry.second;  // a plain variable: lambdas may not capture a binding (C++17)
    if (parents >= kRefineParents) break;
    const auto e = parse_expr_term(scored[k].spec);
    if (!e || e->signal().has_free() || e->signal().transforms.size() >= kMaxChain ||
        at_slow_edge(scored[k].spec, search))
      continue;
    ++parents;
    const SignalExpr& sig = e->signal();
    auto child = [&](const Transform& t, bool front) {
      for (const auto& have : sig.transforms)
        if (have.kind == t.kind) return;  // one of each kind in a chain
      SignalExpr c = sig;
      if (front) {
        c.transforms.insert(c.transforms.begin(), t);
      } else {
        c.transforms.push_back(t);
      }
      const ExprTerm term(e->projection(), c);
      const std::string spec = term.spec();
      if (shapes.count(term.shape()) || !seen->insert(spec).second) return;
      out.push_back({spec, "chain (grammar search)", jobs[k].channel});
    };
    child({TransformKind::LowPass, 0.0, true}, false);
    child({TransformKind::Derivative, 0.0, false}, false);
    bool level_units = true;  // sat(?) is scanned over the source's range: not after d or int
    for (const auto& t : sig.transforms) {
      if (t.kind == TransformKind::Derivative || t.kind == TransformKind::Integral ||
          t.kind == TransformKind::Decay || t.kind == TransformKind::HighPass)
        level_units = false;
    }
    if (level_units) child({TransformKind::Saturate, 0.0, true}, false);
    // x² only where x varies by a good part of its level (elsewhere it is x rescaled, a way
    // around the ridge, not a new shape: 5 V ± noise squared); |x| only where x takes both
    // signs (elsewhere it is x itself).
    const SignalRange range = signal_range(sig, search.data);
    if (range.hi - range.lo >= 0.5 * std::max(std::abs(range.lo), std::abs(range.hi)))
      child({TransformKind::Power, 2.0, false}, true);
    if (range.lo < 0) child({TransformKind::Abs, 0.0, false}, true);
  }
  return out;
}

constexpr size_t kScreenedProducts = 12;  // pairs fitted in full after the screen

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
  for (const Job& j : taken) already.insert(j.spec);
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
    Job j{"field:" + xa + "*" + xb, "product of two channels", xa + "*" + xb};
    if (already.count(j.spec)) continue;
    jobs.push_back(j);
  }
  return jobs;
}

// Every scored job becomes a candidate (each term once), with its fit counted.
void add_candidates(const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                    const Search& search, Diagnosis* dx) {
  std::set<std::string> seen;
  for (size_t k = 0; k < jobs.size(); ++k) {
    dx->candidates_tried += std::max(scored[k].fits, 1L);
    if (!scored[k].note.empty()) dx->notes.push_back(scored[k].note);
    if (!scored[k].ok || !seen.insert(scored[k].spec).second) continue;
    const auto term = make_term(scored[k].spec);
    Candidate c;
    c.term = term->spec();
    c.effect = term->effect();
    c.channel = jobs[k].channel;
    c.family = jobs[k].family;
    c.std_after_nT = scored[k].held;
    c.explained_selection = share(scored[k].sel, search.base_std[0]);
    c.explained_confirmation = share(scored[k].conf, search.base_std[1]);
    c.slow = scored[k].slow;
    if (const auto* e = dynamic_cast<const ExprTerm*>(term.get())) {
      c.estimate = e->size_in_words(scored[k].coef);
      c.parameters = e->parameters();
      c.parameters.emplace_back("gain_nT_per_unit", scored[k].coef.norm());
    }
    if (c.slow) c.estimate += (c.estimate.empty() ? "" : ", ") + std::string("slow stage");
    dx->candidates.push_back(c);
  }
}

// A channel's term without a delay of its own (the partner a scalar lag is judged with).
std::string undelayed(const std::string& term) {
  const auto e = parse_expr_term(term);
  if (!e) return term;
  SignalExpr sig = e->signal();
  sig.transforms.erase(
      std::remove_if(sig.transforms.begin(), sig.transforms.end(),
                     [](const Transform& t) { return t.kind == TransformKind::Delay; }),
      sig.transforms.end());
  if (sig.transforms.empty() && sig.sources.size() == 1) return plain_spec(sig.sources[0]);
  return ExprTerm(e->projection(), sig).spec();
}

// The lag, alone; and, when the best candidate so far is a channel's term, together with that
// channel's term without a delay of its own: a scalar lag delays the channel's signature too,
// and the pair may explain more than the delayed term (round 1 adds the lag, round 2 the term).
void add_lag_candidate(const Model& model, const FlightData& data, const Search& search,
                       Diagnosis* dx) {
  double tau = 0;
  Scored lag = search.lag_candidate(&tau, Eigen::MatrixXd(data.size(), 0));
  dx->candidates_tried += lag.fits;
  double lag_pair_share = NAN;
  std::string partner_note;
  const Candidate* best = nullptr;
  for (const auto& c : dx->candidates) {
    if (!best || c.explained_selection > best->explained_selection) best = &c;
  }
  if (best && !best->channel.empty() && best->channel != model.scalar) {
    const std::string partner = undelayed(best->term);
    double tau2 = 0;
    const Scored pair = search.lag_candidate(&tau2, search.columns_of(partner, false));
    dx->candidates_tried += pair.fits;
    const double pair_share = share(pair.sel, search.base_std[0]);
    if (pair.ok && pair_share > best->explained_selection + 0.01) {
      lag = search.lag_at(tau2, Eigen::MatrixXd(data.size(), 0));  // the lag by itself there
      tau = tau2;
      char buf[160];
      std::snprintf(buf, sizeof(buf), "; with %s next: %.1f%% together", partner.c_str(),
                    100 * pair_share);
      partner_note = buf;
      lag_pair_share = pair_share;
    }
  }
  if (!lag.ok) return;
  const auto term = make_term("lag:" + std::to_string(tau));
  Candidate c;
  c.term = term->spec();
  c.effect = term->effect();
  c.family = "scalar lag";
  c.std_after_nT = lag.held;
  c.explained_selection = share(lag.sel, search.base_std[0]);
  c.explained_confirmation = share(lag.conf, search.base_std[1]);
  std::ostringstream est;
  est.precision(3);
  est << "scalar late by " << tau << " s";
  if (model.scalar_lag_s() != 0.0) est << " (model: " << model.scalar_lag_s() << ")";
  c.estimate = est.str() + partner_note;
  c.parameters = {{"lag_s", tau}};
  c.ranking_share = std::isfinite(lag_pair_share) ? lag_pair_share : c.explained_selection;
  dx->candidates.push_back(c);
}

// Acceptance on both halves, then the ranking: accepted first, by their share on the selection
// lines; among the accepted within one percentage point of the best, the simplest first
// (nrml_acc before nrml_acc*vol_res_p).
void judge_and_rank(const Search& search, const DiagnoseOptions& options,
                    std::vector<Candidate>* candidates) {
  // The std a term removes on split `fold` (0 selection, 1 confirmation), nT.
  auto gain_nT = [&search](int fold, double share) {
    return search.base_std[fold] * (1 - std::sqrt(std::max(0.0, 1 - share)));
  };
  // Both splits by accept_fraction of the variance, and `fold` by the resolution.
  auto passes = [&](const Candidate& c, int fold) {
    return c.explained_selection >= options.accept_fraction &&
           c.explained_confirmation >= options.accept_fraction &&
           gain_nT(fold, fold == 0 ? c.explained_selection : c.explained_confirmation) >=
               options.resolution_nT;
  };
  for (auto& c : *candidates) {
    if (!std::isfinite(c.ranking_share)) c.ranking_share = c.explained_selection;
    c.explained_fraction = std::min(c.explained_selection, c.explained_confirmation);
    c.accepted = passes(c, 0) && passes(c, 1);
  }
  std::stable_sort(candidates->begin(), candidates->end(),
                   [](const Candidate& a, const Candidate& b) {
                     if (a.accepted != b.accepted) return a.accepted;
                     return a.ranking_share > b.ranking_share;
                   });
  if (candidates->empty() || !candidates->front().accepted) return;
  put_simplest_first(candidates, [](const Candidate& lead, const Candidate& c) {
    return c.accepted && c.ranking_share >= lead.ranking_share - 0.01;
  });
  // The confirmation lines choose too. An effect that lives in a few lines (a current switched
  // on in some of them) may barely show on the selection lines, where a look-alike ranks first.
  // The best candidate on the confirmation lines -- lowering their error by the resolution, the
  // selection lines' by at least accept_fraction of the variance, and all held-out lines' by
  // the resolution -- takes the place of the selection lines' choice when it leaves a held-out
  // error lower by the resolution: either way a term is chosen on one half and confirmed on the
  // other, and a term replaces one, never adds one where the selection lines accept none.
  const Candidate& lead = candidates->front();
  // A lag ranked with the channel term whose timing it explains is worth that pair, which its
  // own held-out error does not show: it keeps its place.
  if (lead.ranking_share > lead.explained_selection) return;
  size_t pick = candidates->size();
  for (size_t k = 0; k < candidates->size(); ++k) {
    const Candidate& c = (*candidates)[k];
    if (!passes(c, 1) || search.base_std[2] - c.std_after_nT < options.resolution_nT) continue;
    // Best on the confirmation lines; within one percentage point, the simplest.
    const Candidate* p = pick < candidates->size() ? &(*candidates)[pick] : nullptr;
    if (!p || c.explained_confirmation > p->explained_confirmation + 0.01 ||
        (c.explained_confirmation >= p->explained_confirmation - 0.01 &&
         term_complexity(c.term) < term_complexity(p->term)))
      pick = k;
  }
  if (pick == 0 || pick == candidates->size() ||
      !((*candidates)[pick].std_after_nT <= lead.std_after_nT - options.resolution_nT))
    return;
  (*candidates)[pick].accepted = true;
  (*candidates)[pick].chosen_on_confirmation = true;
  std::rotate(candidates->begin(), candidates->begin() + static_cast<long>(pick),
              candidates->begin() + static_cast<long>(pick) + 1);
}

// What remains: the base residual on the held-out lines (each line's mean removed) against a
// flexible model of the source channels.
ExplainableShare remaining_share(const FlightData& data, const Search& search,
                                 const std::vector<std::string>& sources, double baseline_std_nT,
                                 double resolution_nT) {
  Eigen::VectorXd r = Eigen::VectorXd::Constant(data.size(), NAN);
  std::map<double, std::pair<double, double>> mean;
  for (Eigen::Index i : search.held) {
    auto& m = mean[search.line[i]];
    m.first += search.e0[i];
    m.second += 1;
  }
  for (Eigen::Index i : search.held) {
    const auto& m = mean[search.line[i]];
    r[i] = search.e0[i] - m.first / m.second;
  }
  std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>> channels;
  for (const auto& s : sources) channels.emplace_back(s, data.column(s));
  ExplainableShare x =
      explainable_share(r, search.unit, search.line, data.tt(), search.inputs.direction, channels,
                        [&data] { data.drop_mapped_pages(); });
  // A predictable remainder below the resolution is noise for every practical purpose.
  if (std::sqrt(std::max(0.0, x.share)) * baseline_std_nT < resolution_nT) x.within_noise = true;
  return x;
}

// "complete" only while the held-out residual is within this factor of its own noise floor (or,
// for a floor far below the resolution, within the resolution of it).
constexpr double kCompleteWithinFloor = 1.5;

// What is known of a residual no term explains: how far above its floor, what predicts it,
// whether it follows position (map or trajectory leakage), and what its power follows.
std::string remainder_description(const Diagnosis& dx) {
  const ExplainableShare& x = dx.explainable;
  const ResidualFloor& f = dx.floor;
  std::ostringstream o;
  o.setf(std::ios::fixed);
  o.precision(3);
  o << "the held-out residual is " << f.residual_std_nT << " nT, " << f.residual_std_nT - f.floor_nT
    << " nT above a noise floor of " << f.floor_nT << " nT (its spectrum's white level above "
    << std::setprecision(1) << f.band_lo_hz << " Hz)";
  const bool predictable = x.computed && !x.within_noise;
  if (predictable) {
    std::vector<std::string> chans;
    bool position = false;
    for (size_t k = 0; k < x.channels.size() && chans.size() < 3; ++k) {
      if (x.channels[k].second <= 0) break;
      chans.push_back(x.channels[k].first);
      if (chans.size() == 1) position = is_position_channel(x.channels[k].first);
    }
    o << std::setprecision(1) << "; " << 100 * x.share << "% +- " << 100 * x.uncertainty
      << "% of it is predictable (noise floor " << 100 * x.noise_floor << "%)";
    if (!chans.empty()) {
      o << ", mostly from ";
      for (size_t k = 0; k < chans.size(); ++k) o << (k ? ", " : "") << chans[k];
    }
    if (position) {
      o << ": it follows position, so it is map or trajectory leakage (the reference fit, IGRF "
           "or diurnal), not an aircraft field";
    } else {
      o << ", and no term of the search explains it";
    }
    if (!x.time_scales.empty()) {
      const auto top =
          std::max_element(x.time_scales.begin(), x.time_scales.end(),
                           [](const auto& a, const auto& b) { return a.second < b.second; });
      o << "; mostly " << top->first;
    }
  } else if (x.computed) {
    o << "; no recorded channel predicts its sign";
  }
  if (!f.amplitude_channel.empty()) {
    o << std::setprecision(2) << "; its amplitude follows " << f.amplitude_channel
      << " (rank correlation of the local variance " << f.amplitude_correlation << ")";
    if (x.computed && !predictable) o << ": its phase is not recorded";
  }
  return o.str();
}

// The verdict: add the top term, or complete (within the floor), or what remains and where.
std::string verdict_of(const Diagnosis& dx, double resolution_nT) {
  char buf[512];
  const ExplainableShare& x = dx.explainable;
  if (!dx.candidates.empty() && dx.candidates.front().accepted &&
      dx.candidates.front().explained_fraction >= 0.05) {
    const Candidate& c = dx.candidates.front();
    if (c.chosen_on_confirmation) {
      std::snprintf(buf, sizeof(buf),
                    "add %s: it explains %.1f%% of the held-out error on the confirmation lines "
                    "(where it ranks first) and %.1f%% on the selection lines; the held-out "
                    "error falls from %.3f to %.3f nT",
                    c.term.c_str(), 100 * c.explained_confirmation, 100 * c.explained_selection,
                    dx.baseline_std_nT, c.std_after_nT);
      return buf;
    }
    std::snprintf(buf, sizeof(buf),
                  "add %s: it explains %.1f%% of the held-out error on the selection lines and "
                  "%.1f%% on the confirmation lines",
                  c.term.c_str(), 100 * c.explained_selection, 100 * c.explained_confirmation);
    return buf;
  }
  const ResidualFloor& f = dx.floor;
  if (f.computed) {
    if (f.residual_std_nT <=
        std::max(kCompleteWithinFloor * f.floor_nT, f.floor_nT + resolution_nT)) {
      std::snprintf(buf, sizeof(buf),
                    "complete: the held-out residual (%.3f nT) is within %.1fx its noise floor "
                    "(%.3f nT, its spectrum's white level above %.1f Hz) or %.3f nT of it",
                    f.residual_std_nT, kCompleteWithinFloor, f.floor_nT, f.band_lo_hz,
                    resolution_nT);
      return buf;
    }
    return "structure remains: " + remainder_description(dx);
  }
  if (x.computed && !x.within_noise) {
    std::string chans;
    for (size_t k = 0; k < x.channels.size() && k < 3; ++k) {
      if (x.channels[k].second <= 0) break;
      chans += (k ? ", " : "") + x.channels[k].first;
    }
    std::snprintf(buf, sizeof(buf),
                  "structure remains: %.1f%% ± %.1f%% of the held-out residual is predictable "
                  "(noise floor %.1f%%), mostly from %s, and no term of the search explains it",
                  100 * x.share, 100 * x.uncertainty, 100 * x.noise_floor,
                  chans.empty() ? "no single channel" : chans.c_str());
    return buf;
  }
  if (x.computed) {
    std::snprintf(buf, sizeof(buf),
                  "complete: what remains is within noise (predictable share %.1f%% ± %.1f%%, "
                  "noise floor %.1f%%; predictable part %.3f nT rms, resolution %.3f nT; the "
                  "held-out lines are too short for a spectral floor)",
                  100 * x.share, 100 * x.uncertainty, 100 * x.noise_floor,
                  std::sqrt(x.share) * dx.baseline_std_nT, resolution_nT);
    return buf;
  }
  return "no candidate explains 5 % on both halves (the explainable share was not computed)";
}

// The base residual's floor and what its power follows, on the held-out samples.
ResidualFloor floor_of(const FlightData& data, const Search& search,
                       const std::vector<std::string>& sources) {
  Eigen::VectorXd r = Eigen::VectorXd::Constant(data.size(), NAN);
  for (Eigen::Index i : search.held) r[i] = search.e0[i];
  std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>> channels;
  for (const auto& s : sources) channels.emplace_back(s, data.column(s));
  return residual_floor(r, search.unit, 1.0 / search.dt, channels);
}

}  // namespace

Diagnosis diagnose(const Model& model_in, const FlightData& data, const std::string& truth_name,
                   const DiagnoseOptions& options) {
  const Model model = prepared_model(model_in, data, truth_name);
  Diagnosis dx;
  // Each step copies the columns it reads: between steps the file's pages need not stay
  // resident (they are mapped again when read).
  const Search search(model, data, truth_name, &dx);
  const std::vector<std::string> sources =
      source_fields(model, data, truth_name, options.full_search, &dx.notes);
  data.drop_mapped_pages();
  // Position and trajectory channels are no source of aircraft field: never a term (the
  // explainable share still reads them, to report leakage).
  std::vector<std::string> aircraft_sources;
  for (const auto& s : sources)
    if (!is_position_channel(s)) aircraft_sources.push_back(s);
  std::vector<Job> jobs = make_jobs(model, aircraft_sources);
  std::vector<Scored> scored = run_jobs(search, jobs, options.threads);
  std::vector<Job> products = product_jobs(model, search, jobs, scored, options.accept_fraction);
  if (options.full_search) {
    const std::vector<Job> screened =
        screened_products(search, aircraft_sources, products, kScreenedProducts, options.threads);
    products.insert(products.end(), screened.begin(), screened.end());
  }
  if (!products.empty()) {
    std::vector<Scored> more = run_jobs(search, products, options.threads);
    jobs.insert(jobs.end(), products.begin(), products.end());
    scored.insert(scored.end(), more.begin(), more.end());
  }
  {  // the grammar search, best-first: two levels
    std::set<std::string> seen;
    for (const auto& j : jobs) seen.insert(j.spec);
    for (const auto& x : scored) seen.insert(x.spec);
    std::vector<Job> grown = refined_jobs(model, search, jobs, scored, &seen);
    for (int level = 0; level < 2 && !grown.empty(); ++level) {
      std::vector<Scored> more = run_jobs(search, grown, options.threads);
      for (auto& x : more)
        if (x.ok && at_slow_edge(x.spec, search)) x.ok = false;
      jobs.insert(jobs.end(), grown.begin(), grown.end());
      scored.insert(scored.end(), more.begin(), more.end());
      grown = level == 0 ? refined_jobs(model, search, grown, more, &seen) : std::vector<Job>{};
    }
  }
  data.drop_mapped_pages();
  add_candidates(jobs, scored, search, &dx);
  add_lag_candidate(model, data, search, &dx);
  judge_and_rank(search, options, &dx.candidates);
  data.drop_mapped_pages();
  dx.associations = residual_associations(data, search.held, search.e0, search.line, truth_name);
  data.drop_mapped_pages();
  if (options.explainable_share) {
    dx.explainable =
        remaining_share(data, search, sources, dx.baseline_std_nT, options.resolution_nT);
  }
  dx.floor = floor_of(data, search, sources);
  data.drop_mapped_pages();
  dx.verdict = verdict_of(dx, options.resolution_nT);
  return dx;
}

}  // namespace magcomp
