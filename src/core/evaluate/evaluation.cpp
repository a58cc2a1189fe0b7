// magcomp: error statistics.
#include "magcomp/core/evaluate/evaluation.h"

#include <cmath>
#include <cstdio>
#include <future>
#include <limits>
#include <map>
#include <mutex>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/flight_conditions.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/neural/network.h"

namespace magcomp {

namespace {

// Running sums of one line's errors (nT).
struct LineSums {
  Eigen::Index n = 0;
  double sum = 0, sum_sq = 0;
};

// The line of sample i (0 without a line field, -1 for a NaN line).
double line_of(const double* line_column, Eigen::Index i) {
  const double line = line_column ? line_column[i] : 0.0;
  return std::isfinite(line) ? line : -1.0;
}

// Each line's sums over the finite errors error_at(i), i < n; the non-finite ones counted in
// *nan_samples.
template <class ErrorAt>
std::map<double, LineSums> line_sums(Eigen::Index n, const ErrorAt& error_at,
                                     const double* line_column, Eigen::Index* nan_samples) {
  std::map<double, LineSums> groups;
  // Consecutive samples are mostly on one line: a run's sums are held here and stored in its
  // line's entry when the line changes (the same additions in the same order).
  LineSums* target = nullptr;
  LineSums run;
  double run_line = 0.0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double e = error_at(i);
    if (!std::isfinite(e)) {
      ++*nan_samples;
      continue;
    }
    const double line = line_of(line_column, i);
    if (!target || line != run_line) {
      if (target) *target = run;
      target = &groups[line];
      run = *target;
      run_line = line;
    }
    run.n++;
    run.sum += e;
    run.sum_sq += e * e;
  }
  if (target) *target = run;
  return groups;
}

// The per-line table and the pooled figures of `groups` into *ev.
void line_table(const std::map<double, LineSums>& groups, Evaluation* ev) {
  double total_sq = 0, total_var = 0;
  for (const auto& [line, a] : groups) {
    LineStats s;
    s.line = line;
    s.n = a.n;
    const double mean = a.sum / static_cast<double>(a.n);
    const double ss_dev = std::max(0.0, a.sum_sq - a.n * mean * mean);
    s.rmse_nT = std::sqrt(a.sum_sq / static_cast<double>(a.n));
    s.std_nT = a.n > 1 ? std::sqrt(ss_dev / static_cast<double>(a.n - 1)) : NAN;  // no spread
    ev->per_line.push_back(s);
    ev->n += a.n;
    total_sq += a.sum_sq;
    total_var += ss_dev;
  }
  if (ev->n > 0) {
    ev->rmse_nT = std::sqrt(total_sq / static_cast<double>(ev->n));
    ev->std_nT = std::sqrt(total_var / static_cast<double>(ev->n));
  }
}

// The std by flight condition and by heading sector, each line's mean removed first.
void condition_and_heading_stats(const FlightData& data, const Eigen::VectorXd& error_nT,
                                 const double* line_column, std::map<double, LineSums>& groups,
                                 const std::vector<FlightCondition>& cond, Evaluation* ev) {
  const double* yaw = data.has("ins_yaw") ? data.column("ins_yaw").data() : nullptr;
  std::vector<double> ss_c(kConditionCount, 0), ss_h(8, 0);
  std::vector<Eigen::Index> n_c(kConditionCount, 0), n_h(8, 0);
  // A sum per condition and per sector, added to in sample order; the current run of one
  // condition (and of one sector) is summed here and stored when it ends.
  struct Run {
    std::vector<double>* sums;
    std::vector<Eigen::Index>* counts;
    size_t key = 0;
    double sum = 0;
    Eigen::Index count = 0;
    bool open = false;
    void add(size_t k, double v) {
      if (!open || k != key) {
        close();
        key = k;
        sum = (*sums)[k];
        count = (*counts)[k];
        open = true;
      }
      sum += v;
      ++count;
    }
    void close() {
      if (!open) return;
      (*sums)[key] = sum;
      (*counts)[key] = count;
      open = false;
    }
  };
  Run by_condition{&ss_c, &n_c}, by_sector{&ss_h, &n_h};
  const LineSums* target = nullptr;
  double run_line = 0.0, mean = 0.0;
  for (Eigen::Index i = 0; i < error_nT.size(); ++i) {
    if (!std::isfinite(error_nT[i])) continue;
    const double line = line_of(line_column, i);
    if (!target || line != run_line) {
      target = &groups[line];
      run_line = line;
      mean = target->sum / static_cast<double>(target->n);
    }
    const double d = error_nT[i] - mean;
    by_condition.add(static_cast<size_t>(cond[static_cast<size_t>(i)]), d * d);
    const int h = yaw ? heading_sector(yaw[i]) : -1;
    if (h >= 0) by_sector.add(static_cast<size_t>(h), d * d);
  }
  by_condition.close();
  by_sector.close();
  for (int c = 0; c < kConditionCount; ++c) {
    const auto k = static_cast<size_t>(c);
    if (n_c[k] == 0) continue;
    ev->per_condition.push_back({condition_name(static_cast<FlightCondition>(c)), n_c[k],
                                 std::sqrt(ss_c[k] / static_cast<double>(n_c[k]))});
  }
  for (int h = 0; h < 8; ++h) {
    const auto k = static_cast<size_t>(h);
    if (n_h[k] == 0) continue;
    ev->per_heading.push_back(
        {sector_name(h), n_h[k], std::sqrt(ss_h[k] / static_cast<double>(n_h[k]))});
  }
}

}  // namespace

Evaluation error_statistics(const FlightData& data, Eigen::VectorXd error, bool by_condition,
                            const std::vector<FlightCondition>* conditions) {
  Evaluation ev;
  ev.error_nT = std::move(error);
  const Eigen::VectorXd& error_nT = ev.error_nT;
  const double* line_column = data.has("line") ? data.column("line").data() : nullptr;
  std::map<double, LineSums> groups = line_sums(
      error_nT.size(), [&error_nT](Eigen::Index i) { return error_nT[i]; }, line_column,
      &ev.nan_samples);
  line_table(groups, &ev);
  if (by_condition && data.has("tt") && data.size() > 2) {
    std::vector<FlightCondition> classified;
    if (!conditions) classified = classify_conditions(data);
    condition_and_heading_stats(data, error_nT, line_column, groups,
                                conditions ? *conditions : classified, &ev);
  }
  return ev;
}

void require_scorable(const Evaluation& ev, const std::string& source, const std::string& what) {
  const auto lines = static_cast<Eigen::Index>(ev.per_line.size());
  const Eigen::Index dof = ev.n - lines;
  if (dof < kMinDegreesOfFreedom)
    throw Error(source + ": " + what + " has " + std::to_string(ev.n) + " finite sample(s) in " +
                std::to_string(lines) +
                " line(s): " + std::to_string(std::max<Eigen::Index>(dof, 0)) +
                " degree(s) of freedom once each line's mean is removed, " +
                std::to_string(kMinDegreesOfFreedom) + " needed: nothing to score");
  if (!(ev.rmse_nT <= kMaxField_nT) || !(ev.std_nT <= kMaxField_nT)) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.3g", ev.rmse_nT);
    throw Error(source + ": " + what + " has an rms of " + buf +
                " nT, beyond any magnetic field (1e6 nT): the data hold values no magnetometer "
                "gives; nothing to score");
  }
}

double pooled_std(const Eigen::VectorXd& residual, const Eigen::VectorXd& groups) {
  std::map<double, std::pair<double, double>> acc;  // sum, count
  for (Eigen::Index i = 0; i < residual.size(); ++i) {
    if (!std::isfinite(residual[i])) continue;
    auto& a = acc[groups.size() ? groups[i] : 0.0];
    a.first += residual[i];
    a.second += 1;
  }
  double ss = 0, n = 0;
  for (Eigen::Index i = 0; i < residual.size(); ++i) {
    if (!std::isfinite(residual[i])) continue;
    const auto& a = acc[groups.size() ? groups[i] : 0.0];
    const double d = residual[i] - a.first / a.second;
    ss += d * d;
    n += 1;
  }
  return n > 0 ? std::sqrt(ss / n) : 0.0;
}

namespace {

// The model's compensated field, its error against `ref` and its variance (nT, nT^2).
struct Applied {
  Eigen::VectorXd compensated_nT, error_nT, variance_nT2;
};

Applied apply_and_compare(const Model& model, const FlightData& data,
                          const Eigen::Ref<const Eigen::VectorXd>& uncompensated,
                          const FlightData::Column& ref) {
  Applied out;
  const Eigen::Index n = data.size();
  if (model.neural && model.neural->trained()) {
    out.compensated_nT = apply_model(model, data).compensated_nT;
    out.error_nT = out.compensated_nT - ref;
    return out;
  }
  out.compensated_nT.resize(n);
  out.error_nT.resize(n);
  out.variance_nT2.resize(n);
  for_each_correction_block(
      model, data, true,
      [&](Eigen::Index first, const Eigen::VectorXd& correction, const Eigen::VectorXd* variance) {
        for (Eigen::Index k = 0; k < correction.size(); ++k) {
          const Eigen::Index i = first + k;
          const double c = uncompensated[i] - correction[k];
          out.compensated_nT[i] = c;
          out.error_nT[i] = c - ref[i];
        }
        out.variance_nT2.segment(first, variance->size()) = *variance;
      });
  return out;
}

// The share of finite errors, each line's mean removed (as std_nT: a band-pass fit cannot see
// a constant offset), within 1 and 2 sigma of their variance, over the lines of two samples or
// more; NaN without a variance or with fewer than kMinDegreesOfFreedom such samples.
std::pair<double, double> coverage(const Eigen::VectorXd& error, const Eigen::VectorXd& variance,
                                   const double* line) {
  if (variance.size() != error.size()) return {NAN, NAN};
  std::map<double, std::pair<double, double>> acc;  // sum, count per line
  for (Eigen::Index i = 0; i < error.size(); ++i)
    if (std::isfinite(error[i]) && std::isfinite(variance[i]) && variance[i] > 0) {
      auto& a = acc[line ? line[i] : 0.0];
      a.first += error[i];
      a.second += 1;
    }
  long covered = 0, in1 = 0, in2 = 0;
  for (Eigen::Index i = 0; i < error.size(); ++i) {
    if (!(std::isfinite(error[i]) && std::isfinite(variance[i]) && variance[i] > 0)) continue;
    const auto& a = acc[line ? line[i] : 0.0];
    if (a.second < 2) continue;  // a line of one sample has no spread to cover
    const double e = error[i] - a.first / a.second;
    ++covered;
    in1 += e * e <= variance[i];
    in2 += e * e <= 4 * variance[i];
  }
  if (covered < kMinDegreesOfFreedom) return {NAN, NAN};
  return {static_cast<double>(in1) / static_cast<double>(covered),
          static_cast<double>(in2) / static_cast<double>(covered)};
}

}  // namespace

Evaluation evaluate_model(const Model& model, const FlightData& data, const std::string& truth,
                          bool keep_variance) {
  if (!data.has(truth)) throw Error(data.source() + ": reference field '" + truth + "' not found");
  require_model_fields_in_range(model, data, {truth});
  const FlightData::Column ref = data.column(truth);
  if (!ref.array().isFinite().any()) {
    throw Error(data.source() + ": reference field '" + truth + "' holds no finite sample");
  }
  // The flight conditions (for the tables and the FOM) while the model is applied.
  auto classified = std::async(std::launch::async, [&data] {
    return data.has("tt") && data.size() > 2 ? classify_conditions(data)
                                             : std::vector<FlightCondition>();
  });
  // The scalar realigned by the model's lag (the column itself without one).
  const double lag_s = model.scalar_lag_s();
  const Eigen::VectorXd shifted =
      lag_s != 0.0 ? aligned_scalar(model, data, lag_s) : Eigen::VectorXd();
  const Eigen::Ref<const Eigen::VectorXd> uncompensated =
      lag_s != 0.0 ? Eigen::Ref<const Eigen::VectorXd>(shifted)
                   : Eigen::Ref<const Eigen::VectorXd>(data.column(model.scalar));
  // The terms' correction, the compensated field, its error and its variance, block by block.
  Applied applied = apply_and_compare(model, data, uncompensated, ref);
  const std::vector<FlightCondition> conditions = classified.get();
  data.drop_mapped_pages();  // the fluxgate, channels and rates are done with
  const double* line_column = data.has("line") ? data.column("line").data() : nullptr;
  // The scalar's figures before compensation and the figure of merit on one thread while the
  // error's tables are formed on this one.
  Evaluation before;
  FigureOfMerit fom;
  auto side = std::async(std::launch::async, [&] {
    line_table(line_sums(
                   data.size(), [&](Eigen::Index i) { return uncompensated[i] - ref[i]; },
                   line_column, &before.nan_samples),
               &before);
    fom = figure_of_merit(data, model.fit, applied.compensated_nT, uncompensated,
                          conditions.empty() ? nullptr : &conditions);
  });
  const auto [c1, c2] = coverage(applied.error_nT, applied.variance_nT2, line_column);
  Evaluation ev = error_statistics(data, std::move(applied.error_nT), true, &conditions);
  side.get();
  ev.fom = std::move(fom);
  ev.uncompensated_std_nT = before.std_nT;
  ev.improvement_ratio = ev.std_nT > 0 ? before.std_nT / ev.std_nT : NAN;
  for (auto& l : ev.per_line) {
    for (const auto& b : before.per_line) {
      if (b.line != l.line) continue;
      l.uncompensated_std_nT = b.std_nT;
      l.improvement_ratio = l.std_nT > 0 ? b.std_nT / l.std_nT : NAN;
    }
  }
  if (keep_variance) ev.variance_nT2 = std::move(applied.variance_nT2);
  ev.coverage_1sigma = c1;
  ev.coverage_2sigma = c2;
  if (ev.n == 0) {
    throw Error(data.source() + ": no sample has a finite compensated value and reference (" +
                model.scalar + ", " + model.vector + "_x/_y/_z, the model's channels, " + truth +
                "): nothing to score");
  }
  // Readings within any magnetic field and an error beyond it: the model's correction is what
  // leaves the range (a term sized where its channel barely moved, read where it moves).
  if (before.n > 0 && before.rmse_nT <= kMaxField_nT &&
      !(ev.rmse_nT <= kMaxField_nT && ev.std_nT <= kMaxField_nT)) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "has an rms of %.3g nT (%.3g nT before the model's correction)",
                  ev.rmse_nT, before.rmse_nT);
    throw Error(data.source() + ": the error of " + model.scalar + " against " + truth +
                " after the model " + buf +
                ", beyond any magnetic field (1e6 nT): the model's correction leaves the range of "
                "any field on this flight (a term sized where its channel barely moved reads it "
                "here far beyond that); nothing to score");
  }
  require_scorable(ev, data.source(), "the error of " + model.scalar + " against " + truth);
  ev.compensated_nT = std::move(applied.compensated_nT);
  return ev;
}

}  // namespace magcomp

namespace magcomp {

std::pair<double, Eigen::Index> holdout_error_variance_nT2(
    const Model& model, const std::vector<const FlightData*>& flights, const std::string& truth,
    Eigen::Index min_rows) {
  double ss = 0.0;
  Eigen::Index used = 0;
  for (const FlightData* f : flights) {
    if (!f->has(truth)) continue;
    std::vector<bool> fitted(static_cast<size_t>(f->size()), false);
    for (Eigen::Index i : f->select(model.fit.lines, model.fit.windows))
      fitted[static_cast<size_t>(i)] = true;
    const Eigen::VectorXd error = compensate(model, *f) - Eigen::VectorXd(f->column(truth));
    Eigen::VectorXd held = Eigen::VectorXd::Constant(f->size(), NAN);
    for (Eigen::Index i = 0; i < f->size(); ++i)
      if (!fitted[static_cast<size_t>(i)]) held[i] = error[i];
    const Eigen::Index n = (held.array().isFinite()).count();
    if (n == 0) continue;
    const Eigen::VectorXd line =
        f->has("line") ? Eigen::VectorXd(f->column("line")) : Eigen::VectorXd();
    const double s = pooled_std(held, line);
    ss += s * s * static_cast<double>(n);
    used += n;
  }
  if (used < min_rows) return {NAN, 0};
  return {ss / static_cast<double>(used), used};
}

}  // namespace magcomp
