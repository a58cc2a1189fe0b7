// magcomp: diagnose's Search: the base refit on the fit rows, and each candidate's columns
// fitted with it and scored on the held-out folds (see search.h).
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
#include "magcomp/core/math/tall_products.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

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

bool step_in_time(const SignalExpr& signal, double threshold, const FlightData& data) {
  if (signal.sources.empty() || signal.transforms.empty() ||
      signal.transforms.front().kind != TransformKind::Step)
    return false;
  size_t missing = 0;
  const Eigen::VectorXd v = signal_sources_product(signal, data, &missing);
  if (missing > 0) return false;
  std::vector<double> on;  // the finite samples in time order: 1 above the threshold
  for (Eigen::Index i = 0; i < v.size(); ++i)
    if (std::isfinite(v[i])) on.push_back(v[i] > threshold ? 1.0 : 0.0);
  double dt_s = 0.1;
  if (data.has("tt") && data.size() > 1) {
    const auto tt = data.column("tt");
    const double span_s = tt[data.size() - 1] - tt[0];
    if (std::isfinite(span_s) && span_s > 0) dt_s = span_s / static_cast<double>(data.size() - 1);
  }
  const auto w = static_cast<size_t>(std::max(1.0, std::round(kClockWindow_s / dt_s)));
  const size_t n = on.size();
  if (n < 4 * w) return false;
  std::vector<double> sum(n + 1, 0.0);  // prefix sums
  for (size_t i = 0; i < n; ++i) sum[i + 1] = sum[i] + on[i];
  // A relay chattering on its control's noise (the threshold within the noise of the level the
  // channel idles at) is on and off all through the flight: however its majority wanders, no
  // single switch in time agrees with most of its samples, where a step in time disagrees only
  // with the chatter of its crossing.
  double agree = 0;
  for (size_t k = 0; k <= n; ++k) {
    const double on_before = sum[k], on_after = sum[n] - sum[k];
    const double off_before = static_cast<double>(k) - on_before;
    const double off_after = static_cast<double>(n - k) - on_after;
    agree = std::max({agree, off_before + on_after, on_before + off_after});
  }
  if (agree < kClockAgreement * static_cast<double>(n)) return false;
  // The majority within w samples either side; a tie keeps the state before.
  std::vector<size_t> changes;
  int state = -1;
  for (size_t i = 0; i < n; ++i) {
    const size_t lo = i > w ? i - w : 0, hi = std::min(n, i + w + 1);
    const double share = (sum[hi] - sum[lo]) / static_cast<double>(hi - lo);
    const int s = share > 0.5 ? 1 : share < 0.5 ? 0 : state;
    if (state >= 0 && s != state) changes.push_back(i);
    if (s >= 0) state = s;
  }
  if (changes.empty()) return false;
  // Changes within two windows of each other are one switch (the chatter of a slow crossing);
  // an even number of them returns to the state before.
  size_t switches = 0, first = 0;
  for (size_t k = 0; k < changes.size(); ++k) {
    const bool ends = k + 1 == changes.size() || changes[k + 1] - changes[k] > 2 * w;
    if (!ends) continue;
    if ((k - first + 1) % 2 == 1) ++switches;
    first = k + 1;
  }
  return switches == 1 && changes.front() >= w && n - changes.back() >= w;
}

bool integral_in_time(const SignalExpr& signal, const FlightData& data) {
  const auto integral =
      std::find_if(signal.transforms.begin(), signal.transforms.end(),
                   [](const Transform& t) { return t.kind == TransformKind::Integral; });
  if (integral == signal.transforms.end() || signal.sources.empty() || !data.has("tt"))
    return false;
  size_t missing = 0;
  const Eigen::VectorXd v = signal_sources_product(signal, data, &missing);
  if (missing > 0) return false;
  const Eigen::VectorXd t_s = data.column("tt");
  const Eigen::VectorXd y =
      apply_transforms(std::vector<Transform>(signal.transforms.begin(), integral + 1), t_s, v)
          .col(0);
  double first = NAN, last = NAN, lo = INFINITY, hi = -INFINITY;
  for (Eigen::Index i = 0; i < y.size(); ++i) {
    if (!std::isfinite(y[i])) continue;
    if (std::isnan(first)) first = y[i];
    last = y[i];
    lo = std::min(lo, y[i]);
    hi = std::max(hi, y[i]);
  }
  return hi > lo && std::abs(last - first) >= kClockIntegralShare * (hi - lo);
}

Search::Search(const Model& m, const FlightData& d, const std::string& truth_name, Diagnosis* dx,
               bool slow_on_lines, bool thresholds_on_selection, bool second_order_on_lines)
    : model(m),
      data(d),
      pin_thresholds(thresholds_on_selection),
      second_order_slow(second_order_on_lines) {
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
  {
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(af0);
    qr.setThreshold(1e-10);
    af0_basis = qr.householderQ() * Eigen::MatrixXd::Identity(af0.rows(), qr.rank());
  }
  {
    Eigen::MatrixXd g = af0.transpose() * af0;
    g.diagonal().array() += fs.lambda;
    band_inv = g.ldlt().solve(Eigen::MatrixXd::Identity(g.rows(), g.cols()));
  }
  yf = stack_runs(fs, dt, y, runs).col(0);
  dx->fit_samples = yf.size();
  profile = std::make_unique<RidgeProfile>(af0, yf, fs.lambda);
  const Eigen::VectorXd c0 = profile->solve(Eigen::MatrixXd(yf.size(), 0), nullptr);
  e0 = scalar - truth - a0 * c0;
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
  // --- The base's slow terms, fitted after the first stage as fit_model does (on the
  // calibration rows and fit.slow_lines).
  slow0 = Eigen::VectorXd::Zero(n);
  Eigen::MatrixXd nuisance = a0;  // what a candidate's slow fit is fitted beside
  {
    const std::vector<Eigen::Index> slow = slow_columns(terms, model.slow_terms);
    Eigen::MatrixXd sc(n, static_cast<Eigen::Index>(slow.size()));
    for (size_t k = 0; k < slow.size(); ++k)
      sc.col(static_cast<Eigen::Index>(k)) = a_all.col(slow[k]);
    // A candidate's slow fit (below): with the base's band-pass and slow columns' span removed.
    if (!slow.empty()) {
      const auto base_runs =
          fs.slow_lines.empty() ? runs : slow_stage_runs(fs, data, a0, Eigen::VectorXd(e0));
      const Eigen::MatrixXd sc0 = sc.unaryExpr([](double v) { return std::isfinite(v) ? v : 0.0; });
      // Each size with the base's coefficients' share of its columns' band content given back,
      // as fit_model gives it back; on the held-out rows, where it is read (the slow stage
      // removes the base's span on the fit rows).
      const Eigen::MatrixXd share = band_share(sc);
      const Eigen::VectorXd cs_all = SlowStage(a0, e0, base_runs, fs.lambda).fit(sc);
      slow0 = sc0 * cs_all - held_product(a0, share, cs_all);
      // Sized on held-out lines too (fit.slow_lines), the slow terms are cross-fitted there as
      // the loop scores them: each half's rows read the size fitted on the calibration rows and
      // the other half's held-out rows, so no held-out figure reads a size fitted on itself.
      if (!fs.slow_lines.empty()) {
        std::vector<Eigen::Index> half_rows[2];
        for (Eigen::Index i : held) half_rows[fold[static_cast<size_t>(i)]].push_back(i);
        const Eigen::RowVectorXd level = held_mean(sc);
        for (int h = 0; h < 2; ++h) {
          const auto other = slow_stage_runs(fs, data, a0, Eigen::VectorXd(e0), &half_rows[1 - h]);
          const Eigen::VectorXd cs = SlowStage(a0, e0, other, fs.lambda).fit(sc);
          const Eigen::VectorXd back = held_product(a0, share, cs);
          const double back_level = held_mean(back)[0];
          for (Eigen::Index i : half_rows[h])
            slow0[i] = (sc0.row(i) - level).dot(cs) - (back[i] - back_level);
        }
      }
      e0 -= slow0;
      nuisance.resize(n, a0.cols() + sc.cols());
      nuisance << a0, sc;
      slow_base_cols = sc;
    }
  }
  dx->heldout_fold.assign(static_cast<size_t>(n), -1);
  for (Eigen::Index i : held) {
    dx->heldout_fold[static_cast<size_t>(i)] =
        static_cast<signed char>(fold[static_cast<size_t>(i)]);
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
  // --- Slow candidates: sized on the calibration rows, or, with the held-out lines too, on the
  // calibration rows and each half's rows (a run per unit), each half scored with the other's.
  // A reference fit sizes every column on the calibration rows unfiltered already: its slow
  // candidates are those sized on the lines too.
  if (fs.method == FitMethod::kBandpass && !slow_on_lines) {
    slow_stage = std::make_shared<SlowStage>(nuisance, e0, runs, fs.lambda);
    slow_runs = runs;
  } else if (slow_on_lines) {
    std::vector<std::pair<Eigen::Index, Eigen::Index>> half_runs[2] = {runs, runs};
    for (size_t k = 0; k < held.size();) {
      size_t end = k + 1;
      while (end < held.size() &&
             unit[static_cast<size_t>(held[end])] == unit[static_cast<size_t>(held[k])])
        ++end;
      half_runs[fold[static_cast<size_t>(held[k])]].emplace_back(held[k], held[end - 1]);
      k = end;
    }
    for (int h = 0; h < 2; ++h)
      slow_cross[h] = std::make_shared<SlowStage>(nuisance, e0, half_runs[h], fs.lambda);
    slow_stage = slow_cross[0];
    slow_runs = half_runs[0];
  }
  dx->baseline_selection_std_nT = base_std[0];
  dx->baseline_confirmation_std_nT = base_std[1];
  dx->baseline_std_nT = base_std[2];
  inputs = make_term_inputs(data, model.vector, model.bt_scale_nT);
}

Eigen::VectorXd Search::held_product(const Eigen::MatrixXd& x, const Eigen::MatrixXd& within,
                                     const Eigen::VectorXd& size) const {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(data.size());
  if (within.rows() != x.cols() || within.rows() == 0) return out;
  const Eigen::VectorXd w = within * size;
  for (Eigen::Index i : held) {
    double v = 0;
    for (Eigen::Index j = 0; j < x.cols(); ++j)
      if (std::isfinite(x(i, j))) v += x(i, j) * w[j];
    out[i] = v;
  }
  return out;
}

Eigen::RowVectorXd Search::held_mean(const Eigen::MatrixXd& cols) const {
  Eigen::RowVectorXd sum = Eigen::RowVectorXd::Zero(cols.cols());
  Eigen::RowVectorXd count = Eigen::RowVectorXd::Zero(cols.cols());
  for (Eigen::Index i : held)
    for (Eigen::Index j = 0; j < cols.cols(); ++j)
      if (std::isfinite(cols(i, j))) {
        sum[j] += cols(i, j);
        count[j] += 1;
      }
  for (Eigen::Index j = 0; j < cols.cols(); ++j) sum[j] = count[j] > 0 ? sum[j] / count[j] : 0.0;
  return sum;
}

double Search::base_span_share(const Eigen::MatrixXd& band) const {
  const double all = band.squaredNorm();
  if (!(all > 0) || !std::isfinite(all)) return NAN;
  return transpose_product(af0_basis, band).squaredNorm() / all;
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

Scored Search::score_slow(const Eigen::MatrixXd& cols, const Eigen::MatrixXd* band) const {
  Scored s;
  // Each half's size: from the other half's lines (cross-fitted), or the calibration rows alone;
  // with what it gives back through the base's coefficients (`back`, on the held-out rows): the
  // base's share of the columns' band content, as fit_model gives it back.
  const SlowStage* stage_for[2] = {slow_cross[0] ? slow_cross[1].get() : slow_stage.get(),
                                   slow_cross[0] ? slow_cross[0].get() : slow_stage.get()};
  const Eigen::MatrixXd share = band ? band_inv * transpose_product(af0, *band) : band_share(cols);
  Eigen::VectorXd size_for[2], back[2];
  for (int h = 0; h < 2; ++h) {
    size_for[h] = stage_for[h]->fit(cols);
    back[h] = held_product(a0, share, size_for[h]);
  }
  const Eigen::VectorXd coef = 0.5 * (size_for[0] + size_for[1]);
  // Each column about its held-out mean: the halves' sizes differ, and a channel's level (a bus
  // at 27.5 V) read with two sizes would split a line's pieces by a constant that no model
  // fitted once carries (every segment's and line's mean is free).
  const Eigen::RowVectorXd level =
      slow_cross[0] ? held_mean(cols) : Eigen::RowVectorXd::Zero(cols.cols());
  double back_level[2] = {0, 0};
  for (int h = 0; slow_cross[0] && h < 2; ++h) back_level[h] = held_mean(back[h])[0];
  Eigen::VectorXd e = Eigen::VectorXd::Constant(data.size(), NAN);
  for (Eigen::Index i : held) {
    const int h = fold[static_cast<size_t>(i)] == 1 ? 1 : 0;
    const Eigen::VectorXd& c = size_for[h];
    double v = e0[i] + back[h][i] - back_level[h];
    for (Eigen::Index j = 0; j < cols.cols(); ++j) {
      if (std::isfinite(cols(i, j))) v -= (cols(i, j) - level[j]) * c[j];
    }
    e[i] = v;
  }
  s.sel = fold_std(e, held, fold, line, 0);
  s.conf = fold_std(e, held, fold, line, 1);
  s.held = fold_std(e, held, fold, line, -1);
  s.coef = coef;
  s.slow = true;
  s.ok = std::isfinite(s.sel) && std::isfinite(s.conf) && std::isfinite(s.held) &&
         size_for[0].allFinite() && size_for[1].allFinite();
  return s;
}

Eigen::MatrixXd Search::band_share(const Eigen::MatrixXd& cols) const {
  return band_inv * transpose_product(af0, stacked(cols));
}

Scored Search::score(const Eigen::MatrixXd& cols, bool slow_ok) const {
  Scored s;
  const Eigen::MatrixXd band = stacked(cols);
  const Eigen::VectorXd coef = profile->solve(band, nullptr);
  const Eigen::Index p = a0.cols(), k = cols.cols();
  Eigen::VectorXd e = Eigen::VectorXd::Constant(data.size(), NAN);
  for (Eigen::Index i : held) {
    // The base's slow terms as the base fitted them (e0 holds the same correction).
    double v = scalar[i] - truth[i] - slow0[i] - a0.row(i).dot(coef.head(p));
    for (Eigen::Index j = 0; j < k; ++j) {
      if (std::isfinite(cols(i, j))) v -= cols(i, j) * coef[p + j];  // no data: no correction
    }
    e[i] = v;
  }
  s.sel = fold_std(e, held, fold, line, 0);
  s.conf = fold_std(e, held, fold, line, 1);
  s.held = fold_std(e, held, fold, line, -1);
  s.coef = coef.tail(k);
  s.base_span_share = base_span_share(band);
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
      Scored slow = score_slow(cols, &band);
      if (slow.ok && (!s.ok || slow.sel < s.sel)) return slow;
    }
  }
  return s;
}

Scored Search::run(const Job& job) const {
  TermPtr term = job.term.shared();
  auto columns = [&](const Term& t) { return columns_of(t); };
  long fits = 0;
  const auto* expr = dynamic_cast<const ExprTerm*>(term.get());
  // The slow stage sizes what heats or drifts with a state of the aircraft (a current, a
  // voltage, a temperature, ...); a slow fit of position, attitude or the field itself against
  // the reference is where map and trajectory leakage would hide.
  bool slow_ok = expr && has_slow_stage() && !expr->signal().sources.empty();
  if (expr) {
    for (const auto& src : expr->signal().sources) slow_ok = slow_ok && is_aircraft_state(src);
  }
  if (expr && expr->signal().has_free()) {
    TransformKind kind = TransformKind::LowPass;
    for (const auto& tr : expr->signal().transforms)
      if (tr.free) kind = tr.kind;
    if (kind == TransformKind::Step) {  // a threshold: scanned over the signal's quantiles
      const std::vector<double> values = signal_values_sorted(expr->signal(), data);
      if (values.empty() || !(values.back() > values.front())) return Scored{};
      const double v = scan_threshold(values, [&](double x) {
        ++fits;
        return fit_rss(columns(*make_term(expr->with_parameters({x}))));
      });
      term = make_term(expr->with_parameters({v}));
      if (step_in_time(expr->signal(), v, data)) return Scored{};
      Eigen::MatrixXd cols = columns(*term);
      Scored s = score(cols, slow_ok);
      if (s.ok && pin_thresholds && share(s.sel, base_std[0]) >= kThresholdRefineShare) {
        const double pinned = threshold_on_selection(*expr, values, v, s.sel, slow_ok, &fits);
        if (pinned != v && !step_in_time(expr->signal(), pinned, data)) {
          TermPtr moved = make_term(expr->with_parameters({pinned}));
          Eigen::MatrixXd moved_cols = columns(*moved);
          Scored m = score(moved_cols, slow_ok);
          ++fits;
          if (m.ok && m.sel < s.sel) {
            s = std::move(m);
            term = std::move(moved);
            cols = std::move(moved_cols);
          }
        }
      }
      s.term = term;
      if (!(cols.array().isFinite().any())) s.ok = false;
      s.fits = fits + 1;
      return s;
    }
    const SignalRange range =
        in_signal_units(kind) ? signal_range(expr->signal(), data) : SignalRange{};
    std::vector<double> grid = parameter_grid(kind, dt, span, range.hi - range.lo, range.lo);
    if (grid.empty()) return Scored{};
    bool motion_only = !expr->signal().sources.empty();
    for (const auto& src : expr->signal().sources)
      motion_only = motion_only && is_motion_channel(src);
    if (kind == TransformKind::LowPass && motion_only) {
      grid.erase(std::remove_if(grid.begin(), grid.end(),
                                [](double v) { return v > kMaxMotionLowPass_s + 1e-9; }),
                 grid.end());
      if (grid.empty()) return Scored{};
    }
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
        TermPtr slow_term = make_term(expr->with_parameters({vs}));
        Scored ss = score_slow(columns(*slow_term));
        ss.term = slow_term;
        TermPtr band_term = make_term(expr->with_parameters({v}));
        const Eigen::MatrixXd band_cols = columns(*band_term);
        Scored sb = score(band_cols, true);
        sb.term = band_term;
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
  if (const auto* chosen = dynamic_cast<const ExprTerm*>(term.get());
      chosen && integral_in_time(chosen->signal(), data)) {
    Scored none;
    none.fits = fits;
    return none;
  }
  const Eigen::MatrixXd cols = columns(*term);
  Scored s = score(cols, slow_ok);
  // TL's second-order term: 15 columns beside TL's 18 that two minutes of maneuvers cannot size
  // (the band-pass fit there leaves the held-out lines worse than TL); sized on the lines too,
  // cross-fitted, it writes what TL's linearisation drops rather than a channel standing in.
  if (!expr && second_order_slow && slow_cross_fitted() && term->spec() == "second_order") {
    Scored ss = score_slow(cols);
    if (ss.ok && (!s.ok || ss.sel < s.sel)) s = std::move(ss);
  }
  s.term = term;
  s.fits = fits + 1;
  if (!(cols.array().isFinite().any())) s.ok = false;
  return s;
}

double share(double after, double before) {
  return before > 0 ? 1.0 - (after / before) * (after / before) : 0.0;
}

}  // namespace magcomp::diagnose_search
