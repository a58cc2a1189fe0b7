// magcomp_train (also run as `magcomp train`): trains the neural stage of a model on whole
// flights and writes a bundle: the model YAML (features, normalisation, window, terms, version)
// and the weights file beside it.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <iostream>

#include "attribution_output.h"
#include "common.h"
#include "magcomp/core/apply/apply.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/network_gain.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/neural/attribution.h"
#include "magcomp/core/neural/network.h"
#include "magcomp/neural/trainer.h"

namespace {

using namespace magcomp;

double rms(const Eigen::VectorXd& v) {
  double s = 0;
  int n = 0;
  for (Eigen::Index i = 0; i < v.size(); ++i)
    if (std::isfinite(v[i])) s += v[i] * v[i], ++n;
  return n ? std::sqrt(s / n) : NAN;
}

// What `magcomp_train` is asked, as given on the command line.
struct TrainArgs {
  std::vector<std::string> data, validation;
  std::string model_path, neural_from, out;
  int epochs = 0;
  long long seed = -1;
  double channel_sparsity = -1;  // < 0: the model's own
  double channel_cut = -1;       // < 0: the model's own
  bool quiet = false;
};

// The model whose neural stage is trained, with --epochs and --seed applied and validated.
Model model_to_train(const TrainArgs& a) {
  Model model = load_model_yaml(a.model_path);
  if (!a.neural_from.empty()) {  // physics from --model, the network from this file
    const Model donor = load_model_yaml(a.neural_from);
    if (!donor.neural) throw Error(a.neural_from + ": key 'neural' missing: no network to take");
    model.neural = donor.neural;
  }
  if (!model.neural) throw Error(a.model_path + ": key 'neural' missing: nothing to train");
  NeuralSpec& spec = *model.neural;
  if (a.epochs > 0) spec.training.epochs = a.epochs;
  if (a.seed >= 0) spec.training.seed = static_cast<std::uint64_t>(a.seed);
  if (a.channel_sparsity >= 0) spec.training.channel_sparsity = a.channel_sparsity;
  if (a.channel_cut >= 0) spec.training.channel_cut = a.channel_cut;
  validate_neural_spec(spec, a.neural_from.empty() ? a.model_path : a.neural_from);
  return model;
}

// The training's figures, and each validation flight's error with the terms alone and with the
// network.
void print_training(const Model& model, const BundleReport& rep,
                    const std::vector<FlightData>& val_flights) {
  const TrainResult& r = rep.result;
  const NeuralSpec& s = *model.neural;
  if (rep.tl_fitted_here) {
    std::cout << "TL calibrated on the training flights: " << model.coefficients.size()
              << " coefficients, residual std " << std::setprecision(4)
              << model.report.residual_std_nT << " nT\n";
  }
  std::cout << rep.train_windows << " training windows, " << rep.validation_windows
            << " validation windows\n";
  std::cout << std::fixed << std::setprecision(3) << "trained " << r.epochs_run << " epoch(s) in "
            << r.seconds << " s; kept epoch " << r.best_epoch;
  if (!r.validation_rmse_nT.empty())
    std::cout << " (validation rmse " << s.validation_rmse_nT << " nT)";
  if (r.refit_from_epoch > 0) {
    std::cout << "\nchannel_cut " << s.training.channel_cut << ": kept " << r.kept_channels.size()
              << " channel(s) after the penalised epochs 1-" << r.refit_from_epoch - 1 << " (";
    for (size_t i = 0; i < r.kept_channels.size(); ++i)
      std::cout << (i ? ", " : "") << r.kept_channels[i];
    std::cout << "), cut " << r.cut_channels << ", refit without the penalty from epoch "
              << r.refit_from_epoch;
  }
  if (!r.validation_rmse_nT.empty()) {
    for (size_t i = 0; i < val_flights.size(); ++i) {
      const FlightData& f = val_flights[i];
      if (!f.has(s.reference)) continue;
      Model terms_only = model;
      terms_only.neural.reset();
      const Eigen::VectorXd tl_err = compensate(terms_only, f) - f.column(s.reference);
      const NeuralCompensation nc = neural_compensate(model, f);
      const Eigen::VectorXd nn_err = nc.compensated_nT - f.column(s.reference);
      std::cout << "\n  " << s.validation_flights[i] << ": TL rmse " << rms(tl_err)
                << " nT, with the network " << rms(nn_err) << " nT";
      // The same two errors, each line's mean removed: does the network's gain carry over?
      const NetworkGain g = network_gain(error_statistics(f, tl_err, false),
                                         error_statistics(f, nn_err, false), f.source());
      std::cout << "\n  " << g.verdict;
    }
  }
  const OutputGainFit& og = rep.output_gain;
  if (og.samples > 0) {
    std::cout << "\nthe network's share of the correction, fitted on the validation flight(s): "
              << og.gain << " (terms alone " << og.physics_std_nT << " nT, the network as trained "
              << og.trained_std_nT << " nT, with this share " << og.blended_std_nT
              << " nT; each line's mean removed)";
    if (og.gain == 0.0)
      std::cout << "\n  the network's gain does not carry over to a flight it was not trained "
                   "on: the model's terms alone are kept (output_gain 0)";
  }
  std::cout << "\nwrote " << rep.yaml_path << " and " << rep.weights_path << "\n";
}

// What the network leans on, on each validation flight (flights it was not trained on), from the
// bundle as written at yaml_path.
void print_validation_attribution(const std::string& yaml_path,
                                  const std::vector<FlightData>& val_flights,
                                  const std::vector<std::string>& validation) {
  if (val_flights.empty()) return;
  const Model trained = load_model_yaml(yaml_path);
  for (size_t i = 0; i < val_flights.size(); ++i) {
    std::cout << std::flush;
    try {
      cli::print_attribution(permutation_importance(trained, val_flights[i]), validation[i]);
    } catch (const Error& e) {
      std::printf("\nno attribution on %s: %s\n", validation[i].c_str(), e.what());
    }
  }
  std::fflush(stdout);
}

int run(int argc, char** argv) {
  CLI::App app{"magcomp train: train the neural stage of a model on whole flights"};
  TrainArgs a;
  app.add_option("--data", a.data, "training flight HDF5 file(s), comma-separated or repeated")
      ->required()
      ->delimiter(',');
  app.add_option("--validation", a.validation,
                 "validation flight(s) for early stopping (default: the last --data flight when "
                 "there are two or more)")
      ->delimiter(',');
  app.add_option("--model", a.model_path, "model YAML with a neural: block (TL fitted or not)")
      ->required();
  app.add_option("--neural-from", a.neural_from,
                 "model YAML whose neural: block is trained on --model's terms (e.g. the model "
                 "diagnose --apply wrote, any terms): the network learns what they leave");
  app.add_option("--out", a.out,
                 "OUT.yaml (weights in OUT.pt beside it) or a bundle directory (model.yaml + "
                 "weights.pt)")
      ->required();
  app.add_option("--epochs", a.epochs, "override neural.training.epochs");
  app.add_option("--seed", a.seed, "override neural.training.seed");
  app.add_option("--channel-sparsity", a.channel_sparsity,
                 "override neural.training.channel_sparsity (the group lasso on each recorded "
                 "channel's inputs; 0 off)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--channel-cut", a.channel_cut,
                 "override neural.training.channel_cut (with --channel-sparsity: cut the channels "
                 "whose weights fall below this fraction of the largest channel's, refit the rest "
                 "without the penalty; 0 off)")
      ->check(CLI::Range(0.0, 0.999999));
  app.add_flag("--quiet", a.quiet, "no progress bar");
  CLI11_PARSE(app, argc, argv);

  // Every file read and written, checked before the work (outputs never over an input).
  std::vector<OutputGuard::File> inputs = {{"--model", a.model_path}};
  if (!a.neural_from.empty()) inputs.push_back({"--neural-from", a.neural_from});
  for (const auto& p : a.data) inputs.push_back({"--data", p});
  for (const auto& p : a.validation) inputs.push_back({"--validation", p});
  OutputGuard guard(inputs);
  const std::string& out = a.out;
  const bool to_yaml = out.size() > 5 && out.substr(out.size() - 5) == ".yaml";
  guard.add_output("--out", to_yaml ? out : out + "/model.yaml");
  guard.add_output("--out (weights)",
                   to_yaml ? out.substr(0, out.size() - 5) + ".pt" : out + "/weights.pt");
  Model model = model_to_train(a);
  if (a.validation.empty() && a.data.size() >= 2) {
    a.validation.push_back(a.data.back());
    a.data.pop_back();
  }
  for (const auto& v : a.validation)
    for (const auto& d : a.data)
      if (v == d) throw Error("--validation: " + v + " is also a training flight (leakage)");
  std::vector<FlightData> train_flights, val_flights;
  for (const auto& p : a.data) train_flights.push_back(cli::read_flight(p));
  for (const auto& p : a.validation) val_flights.push_back(cli::read_flight(p));
  {  // a copy or another spelling of a flight is that flight: leakage, or its windows twice
    std::vector<std::pair<std::string, const FlightData*>> named;
    for (const auto& f : train_flights) named.emplace_back("--data", &f);
    for (const auto& f : val_flights) named.emplace_back("--validation", &f);
    cli::require_distinct_flights(named, model.scalar);
  }
  if (val_flights.empty())
    std::cout << "warning: no validation flight: no early stopping, the last epoch is kept\n";
  const NeuralSpec& spec = *model.neural;
  std::cout << "training " << architecture_name(spec.architecture) << " (" << mode_name(spec.mode)
            << ", window " << spec.window << ", " << spec.features.size() << " features) on "
            << train_flights.size() << " flight(s), validation on " << val_flights.size()
            << " flight(s)" << std::endl;
  const BundleReport rep = train_bundle(model, train_flights, val_flights, out, !a.quiet);
  print_training(model, rep, val_flights);
  print_validation_attribution(rep.yaml_path, val_flights, a.validation);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::cli::run_reporting_errors([&] { return run(argc, argv); });
}
