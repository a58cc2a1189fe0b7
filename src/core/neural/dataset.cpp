// magcomp: normalisation and training windows.
#include "magcomp/core/neural/dataset.h"

#include <cmath>

#include "magcomp/core/error.h"

namespace magcomp {
namespace {

void finite_mean_std(const Eigen::Ref<const Eigen::VectorXd>& v, double* sum, double* sum2,
                     double* count) {
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v[i])) continue;
    *sum += v[i];
    *sum2 += v[i] * v[i];
    *count += 1;
  }
}

}  // namespace

std::vector<FlightSamples> flight_samples(const Model& model,
                                          const std::vector<FlightData>& flights) {
  std::vector<FlightSamples> v;
  for (const auto& f : flights) {
    FlightSamples fs;
    fs.inputs = neural_inputs(model, f);
    fs.target_nT = neural_target(model, f, fs.inputs);
    v.push_back(std::move(fs));
    f.drop_mapped_pages();  // its features are built: one flight's file pages at a time
  }
  return v;
}

void fit_normalisation(NeuralSpec& spec, const std::vector<FlightSamples>& training) {
  if (training.empty()) throw Error("train: no training flight");
  const Eigen::Index f = training[0].inputs.features.cols();
  spec.feature_mean.resize(f);
  spec.feature_std.resize(f);
  for (Eigen::Index k = 0; k < f; ++k) {
    double s = 0, s2 = 0, n = 0;
    for (const auto& fl : training) finite_mean_std(fl.inputs.features.col(k), &s, &s2, &n);
    if (n == 0) {
      throw Error("train: neural feature '" + spec.features[static_cast<size_t>(k)] +
                  "' has no finite value on the training flights");
    }
    const double mean = s / n, var = std::max(0.0, s2 / n - mean * mean);
    spec.feature_mean[k] = mean;
    spec.feature_std[k] = var > 1e-24 * std::max(1.0, mean * mean) ? std::sqrt(var) : 1.0;
  }
  double s = 0, s2 = 0, n = 0;
  for (const auto& fl : training) finite_mean_std(fl.target_nT, &s, &s2, &n);
  if (n == 0) throw Error("train: the reference '" + spec.reference + "' has no finite value");
  spec.target_mean = s / n;
  const double var = std::max(0.0, s2 / n - spec.target_mean * spec.target_mean);
  spec.target_std = var > 0 ? std::sqrt(var) : 1.0;
}

Eigen::VectorXd tl_column_scale(const std::vector<FlightSamples>& training) {
  const Eigen::Index p = training.at(0).inputs.tl_columns.cols();
  Eigen::VectorXd scale(p);
  for (Eigen::Index j = 0; j < p; ++j) {
    double s = 0, s2 = 0, n = 0;
    for (const auto& fl : training) finite_mean_std(fl.inputs.tl_columns.col(j), &s, &s2, &n);
    const double rms = n > 0 ? std::sqrt(s2 / n) : 0.0;
    scale[j] = rms > 0 ? rms : 1.0;
  }
  return scale;
}

TrainingData make_training_data(const NeuralSpec& spec, const std::vector<FlightSamples>& flights,
                                const Eigen::VectorXd& tl_scale, int stride) {
  Eigen::Index n = 0;
  for (const auto& fl : flights) n += fl.inputs.features.rows();
  const Eigen::Index f = spec.feature_mean.size(), p = tl_scale.size();
  TrainingData d;
  d.features.resize(n, f);
  d.target.resize(n);
  if (p > 0) d.tl_columns.resize(n, p);
  d.first_row.resize(static_cast<size_t>(n));
  Eigen::Index row = 0;
  std::vector<double> z(static_cast<size_t>(f));
  for (const auto& fl : flights) {
    const Eigen::Index first = row, m = fl.inputs.features.rows();
    for (Eigen::Index i = 0; i < m; ++i, ++row) {
      const Eigen::VectorXd raw = fl.inputs.features.row(i).transpose();
      standardise_features(spec, raw.data(), z.data());
      for (Eigen::Index k = 0; k < f; ++k)
        d.features(row, k) = static_cast<float>(z[static_cast<size_t>(k)]);
      const double t = (fl.target_nT[i] - spec.target_mean) / spec.target_std;
      d.target[row] = static_cast<float>(t);
      for (Eigen::Index j = 0; j < p; ++j) {
        const double a = fl.inputs.tl_columns(i, j) / tl_scale[j];
        d.tl_columns(row, j) = static_cast<float>(std::isfinite(a) ? a : 0.0);
      }
      d.first_row[static_cast<size_t>(row)] = first;
      // A window end needs a finite target and finite TL columns (joint mode) at its sample.
      bool ok = std::isfinite(t) && (i % stride == 0);
      for (Eigen::Index j = 0; ok && j < p; ++j) ok = std::isfinite(fl.inputs.tl_columns(i, j));
      if (spec.mode != NeuralMode::kAnomaly) ok = ok && std::isfinite(fl.inputs.correction_nT[i]);
      if (ok) d.ends.push_back(row);
    }
  }
  return d;
}

}  // namespace magcomp
