// magcomp: training a model's neural stage from flights to a bundle on disk (no torch here).
#include <sys/stat.h>

#include <cerrno>
#include <cmath>
#include <iostream>

#include "magcomp/core/error.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/neural/trainer.h"

// Defined in networks.cpp (this library): the trained network, without going through dlopen.
extern "C" magcomp::NeuralNetwork* magcomp_create_network(const magcomp::NeuralSpec* spec,
                                                          int n_features, std::string* error);

namespace magcomp {
namespace {

std::string base_name(const std::string& p) {
  const auto s = p.find_last_of('/');
  return s == std::string::npos ? p : p.substr(s + 1);
}

}  // namespace

BundleReport train_bundle(Model& model, const std::vector<FlightData>& train_flights,
                          const std::vector<FlightData>& validation_flights, const std::string& out,
                          bool progress) {
  if (!model.neural) throw Error("model: key 'neural' missing: nothing to train");
  if (train_flights.empty()) throw Error("train: no training flight");
  for (const auto& v : validation_flights) {
    for (const auto& t : train_flights) {
      if (v.source() == t.source() && !v.source().empty()) {
        throw Error("--validation: " + v.source() + " is also a training flight (leakage)");
      }
    }
  }
  BundleReport rep;
  // Corrections first: TL, fitted here on the training flights if the model is not calibrated.
  if (!model.fitted()) {
    std::vector<const FlightData*> ptrs;
    for (const auto& f : train_flights) ptrs.push_back(&f);
    const std::optional<NeuralSpec> keep = model.neural;
    fit_model(model, ptrs);
    model.neural = keep;
    rep.tl_fitted_here = true;
  }
  NeuralSpec& s = *model.neural;
  s.tl_delta.resize(0);
  s.column_scale.resize(0);
  const std::vector<FlightSamples> tr = flight_samples(model, train_flights);
  const std::vector<FlightSamples> va = flight_samples(model, validation_flights);
  fit_normalisation(s, tr);  // training flights only
  const bool with_columns = s.mode == NeuralMode::kJoint || s.mode == NeuralMode::kCoefficients;
  const Eigen::VectorXd tl_scale = with_columns ? tl_column_scale(tr) : Eigen::VectorXd();
  if (s.mode == NeuralMode::kCoefficients) s.column_scale = tl_scale;
  TrainingData td = make_training_data(s, tr, tl_scale, s.training.stride);
  if (s.training.channel_sparsity > 0)
    for (auto& group : channel_input_groups(model)) {
      td.channel_names.push_back(group.first);
      td.channel_groups.push_back(group.second);
    }
  // Validation windows on the same stride (early stopping needs a score, not every sample).
  const TrainingData vd = make_training_data(s, va, tl_scale, s.training.stride);
  rep.train_windows = td.windows();
  rep.validation_windows = vd.windows();

  const bool is_yaml = out.size() > 5 && out.substr(out.size() - 5) == ".yaml";
  std::string weights_file;
  if (is_yaml) {
    rep.yaml_path = out;
    weights_file = base_name(out.substr(0, out.size() - 5)) + ".pt";
  } else {
    if (::mkdir(out.c_str(), 0755) != 0 && errno != EEXIST) {
      throw Error(out + ": cannot create the bundle directory");
    }
    rep.yaml_path = out + "/model.yaml";
    weights_file = "weights.pt";
  }
  const auto slash = rep.yaml_path.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : rep.yaml_path.substr(0, slash);
  rep.weights_path = dir + "/" + weights_file;

  rep.result = train_network(s, td, vd, rep.weights_path, progress);
  if (s.mode == NeuralMode::kJoint) {
    s.tl_delta = rep.result.tl_weights.cwiseProduct(tl_scale.cwiseInverse()) * s.target_std;
  }
  s.weights = weights_file;
  s.weights_path = rep.weights_path;
  s.train_flights.clear();
  s.validation_flights.clear();
  for (const auto& f : train_flights) s.train_flights.push_back(base_name(f.source()));
  for (const auto& f : validation_flights) s.validation_flights.push_back(base_name(f.source()));
  s.epochs_run = rep.result.epochs_run;
  s.validation_rmse_nT =
      std::isfinite(rep.result.best_validation_rmse_nT) ? rep.result.best_validation_rmse_nT : 0.0;
  // The network's share of the correction, fitted on the flights it was not trained on: the
  // hybrid is then no worse there than its terms alone.
  s.output_gain = 1.0;
  if (s.training.fit_output_gain && !validation_flights.empty()) {
    std::string error;
    std::shared_ptr<NeuralNetwork> network(
        magcomp_create_network(&s, static_cast<int>(s.feature_mean.size()), &error));
    if (!network) throw Error(rep.weights_path + ": " + error);
    rep.output_gain = fit_output_gain(model, validation_flights, network);
    if (rep.output_gain.samples > 0) s.output_gain = rep.output_gain.gain;
  }
  save_model_yaml(model, rep.yaml_path);
  return rep;
}

}  // namespace magcomp
