// magcomp: loading the neural library and running a trained network offline and online.
#include "magcomp/core/neural/network.h"

#include <dlfcn.h>
#include <unistd.h>

#include <climits>
#include <cmath>
#include <cstdlib>
#include <mutex>

#include "magcomp/core/error.h"
#include "magcomp/core/io/paths.h"
#include "magcomp/core/neural/features.h"

namespace magcomp {
namespace {

CreateNetworkFn create_function() {
  static std::mutex mutex;
  static CreateNetworkFn fn = nullptr;
  std::lock_guard<std::mutex> lock(mutex);
  if (fn) return fn;
  std::vector<std::string> candidates;
  if (const char* env = std::getenv("MAGCOMP_NEURAL_LIB")) candidates.push_back(env);
  const std::string dir = executable_dir();
  candidates.push_back(dir + "/libmagcomp_neural.so");         // installed beside lib/
  candidates.push_back(dir + "/../libmagcomp_neural.so");      // catkin: lib/magcomp/<exe>
  candidates.push_back(dir + "/../lib/libmagcomp_neural.so");  // catkin: bin/<exe>
  candidates.push_back("libmagcomp_neural.so");                // LD_LIBRARY_PATH
  std::string errors;
  for (const auto& c : candidates) {
    void* handle = ::dlopen(c.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
      if (const char* e = ::dlerror()) errors = e;
      continue;
    }
    fn = reinterpret_cast<CreateNetworkFn>(::dlsym(handle, kCreateNetworkSymbol));
    if (fn) return fn;
    errors = c + " has no symbol " + kCreateNetworkSymbol;
  }
  throw Error("neural: cannot load libmagcomp_neural.so (set MAGCOMP_NEURAL_LIB): " + errors);
}

}  // namespace

std::shared_ptr<NeuralNetwork> load_neural_network(const Model& model, int n_features) {
  if (!model.neural || !model.neural->trained()) {
    throw Error("model: the neural stage is not trained (no weights); run magcomp train");
  }
  std::string error;
  NeuralNetwork* net = create_function()(&*model.neural, n_features, &error);
  if (!net) throw Error(model.neural->weights_path + ": " + error);
  return std::shared_ptr<NeuralNetwork>(net);
}

double neural_correction_nT(const NeuralSpec& spec, double scalar_nT, double tl_correction_nT,
                            double tl_delta_nT, double igrf_nT, double diurnal_nT, double y_nT) {
  const double trained = spec.mode == NeuralMode::kAnomaly
                             ? scalar_nT - (igrf_nT + diurnal_nT + y_nT)
                             : tl_correction_nT + tl_delta_nT + y_nT;
  if (spec.output_gain == 1.0) return trained;
  return tl_correction_nT + spec.output_gain * (trained - tl_correction_nT);
}

Eigen::MatrixXd standardised_inputs(const NeuralSpec& s, const Eigen::MatrixXd& features) {
  const Eigen::Index n = features.rows(), f = features.cols();
  Eigen::MatrixXd z(f, n);  // standardised, one sample per column
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::VectorXd raw = features.row(i).transpose();
    standardise_features(s, raw.data(), z.col(i).data());
  }
  return z;
}

// Model columns divided by the spec's column_scale, non-finite values as 0 (as in training).
static void scale_columns(const NeuralSpec& s, const double* a, double* out) {
  for (Eigen::Index j = 0; j < s.column_scale.size(); ++j) {
    const double v = a[j] / s.column_scale[j];
    out[j] = std::isfinite(v) ? v : 0.0;
  }
}

Eigen::VectorXd network_output_nT(const NeuralSpec& s, const Eigen::MatrixXd& z,
                                  NeuralNetwork& network, const Eigen::MatrixXd* columns) {
  const Eigen::Index n = z.cols(), f = z.rows(), k = s.window;
  const bool coefficients = s.mode == NeuralMode::kCoefficients;
  const Eigen::Index p = s.column_scale.size();
  if (coefficients && (!columns || columns->rows() != n || columns->cols() != p))
    throw Error("neural: the coefficients mode needs the model's " + std::to_string(p) +
                " columns at every sample");
  Eigen::VectorXd y(n);
  const Eigen::Index chunk = 2048;
  std::vector<double> windows, scaled;
  for (Eigen::Index start = 0; start < n; start += chunk) {
    const Eigen::Index count = std::min(chunk, n - start);
    windows.assign(static_cast<size_t>(count * k * f), 0.0);
    for (Eigen::Index b = 0; b < count; ++b) {
      for (Eigen::Index j = 0; j < k; ++j) {
        const Eigen::Index src = std::max<Eigen::Index>(0, start + b - (k - 1) + j);
        std::copy(z.col(src).data(), z.col(src).data() + f, windows.data() + (b * k + j) * f);
      }
    }
    if (coefficients) {
      scaled.assign(static_cast<size_t>(count * p), 0.0);
      for (Eigen::Index b = 0; b < count; ++b) {
        const Eigen::RowVectorXd a = columns->row(start + b);
        scale_columns(s, a.data(), scaled.data() + b * p);
      }
    }
    network.predict(windows.data(), count, y.data() + start,
                    coefficients ? scaled.data() : nullptr);
  }
  return y.array() * s.target_std + s.target_mean;
}

NeuralCompensation neural_compensate(const Model& model, const FlightData& data,
                                     std::shared_ptr<NeuralNetwork> network) {
  const NeuralInputs in = neural_inputs(model, data);
  const NeuralSpec& s = *model.neural;
  const Eigen::Index n = data.size(), f = in.features.cols();
  if (!network) network = load_neural_network(model, static_cast<int>(f));
  NeuralCompensation out;
  out.measured_nT = in.scalar_nT;
  out.terms_correction_nT = in.correction_nT;
  out.network_nT =
      network_output_nT(s, standardised_inputs(s, in.features), *network, &in.tl_columns);
  const Eigen::VectorXd delta = s.tl_delta.size() > 0 ? Eigen::VectorXd(in.tl_columns * s.tl_delta)
                                                      : Eigen::VectorXd::Zero(n);
  out.correction_nT.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    out.correction_nT[i] = neural_correction_nT(s, in.scalar_nT[i], in.correction_nT[i], delta[i],
                                                in.igrf_nT[i], in.diurnal_nT[i], out.network_nT[i]);
  }
  out.compensated_nT = out.measured_nT - out.correction_nT;
  return out;
}

Eigen::MatrixXd coefficient_corrections(const Model& model, const FlightData& data,
                                        std::shared_ptr<NeuralNetwork> network) {
  if (!model.neural || model.neural->mode != NeuralMode::kCoefficients)
    throw Error("model: the network does not correct coefficients (neural.mode coefficients)");
  const NeuralSpec& s = *model.neural;
  const NeuralInputs in = neural_inputs(model, data);
  if (!network) network = load_neural_network(model, static_cast<int>(in.features.cols()));
  const Eigen::MatrixXd z = standardised_inputs(s, in.features);
  const Eigen::Index n = z.cols(), p = s.column_scale.size();
  // The prediction is linear in the scaled columns: column j's unit vector reads output j.
  Eigen::MatrixXd out(n, p);
  for (Eigen::Index j = 0; j < p; ++j) {
    Eigen::MatrixXd unit = Eigen::MatrixXd::Zero(n, p);
    unit.col(j).setConstant(s.column_scale[j]);
    out.col(j) =
        (network_output_nT(s, z, *network, &unit).array() - s.target_mean) / s.column_scale[j];
  }
  return out;
}

NeuralStreamer::NeuralStreamer(const NeuralSpec& spec, std::shared_ptr<NeuralNetwork> network)
    : spec_(spec), network_(std::move(network)) {}

double NeuralStreamer::push(const double* raw_features, const double* columns) {
  const size_t f = static_cast<size_t>(spec_.feature_mean.size());
  const size_t k = static_cast<size_t>(spec_.window);
  if (!filled_) {
    window_.resize(k * f);
    standardise_features(spec_, raw_features, window_.data());
    for (size_t j = 1; j < k; ++j) {  // pad with the first row, as the offline path does
      std::copy(window_.begin(), window_.begin() + f, window_.begin() + j * f);
    }
    filled_ = true;
  } else {
    std::copy(window_.begin() + f, window_.end(), window_.begin());  // drop the oldest row
    standardise_features(spec_, raw_features, window_.data() + (k - 1) * f);
  }
  const bool coefficients = spec_.mode == NeuralMode::kCoefficients;
  if (coefficients) {
    if (!columns) throw Error("neural: the coefficients mode needs the sample's model columns");
    columns_.resize(static_cast<size_t>(spec_.column_scale.size()));
    scale_columns(spec_, columns, columns_.data());
  }
  double y = 0.0;
  network_->predict(window_.data(), 1, &y, coefficients ? columns_.data() : nullptr);
  return y * spec_.target_std + spec_.target_mean;
}

}  // namespace magcomp
