// magcomp: network architectures and batch inference (libtorch), and the factory symbol that
// magcomp_core finds with dlopen.
#include "networks.h"

#include <Eigen/Core>
#include <fstream>

#include "magcomp/core/neural/network.h"
#include "magcomp/neural/fused_lstm.h"

namespace magcomp {

CompensatorNetImpl::CompensatorNetImpl(const NeuralSpec& spec, int n_feat, int n_tl)
    : architecture(spec.architecture),
      coefficients(spec.mode == NeuralMode::kCoefficients),
      window(spec.window),
      n_features(n_feat) {
  const std::vector<int> h = spec.hidden_or_default();
  // The body's outputs: one value, or one coefficient correction per model column.
  const int outputs = coefficients ? std::max(n_tl, 1) : 1;
  if (architecture == NeuralArchitecture::kMlp) {
    // The MLP of Laoué's report: the window flattened, ReLU layers (16, 4), one output.
    mlp = torch::nn::Sequential();
    int in = window * n_features;
    for (int width : h) {
      mlp->push_back(torch::nn::Linear(in, width));
      mlp->push_back(torch::nn::ReLU());
      in = width;
    }
    mlp->push_back(torch::nn::Linear(in, outputs));
    register_module("mlp", mlp);
  } else if (architecture == NeuralArchitecture::kCnn) {
    // Two 1-D convolutions over time (filters h[0], h[1], kernel 5), each halved by max pooling.
    conv1 = register_module(
        "conv1", torch::nn::Conv1d(torch::nn::Conv1dOptions(n_features, h[0], 5).padding(2)));
    conv2 = register_module("conv2",
                            torch::nn::Conv1d(torch::nn::Conv1dOptions(h[0], h[1], 5).padding(2)));
    const int len = window / 4;
    cnn_fc1 = register_module("cnn_fc1", torch::nn::Linear(h[1] * len, 32));
    cnn_fc2 = register_module("cnn_fc2", torch::nn::Linear(32, outputs));
  } else if (architecture == NeuralArchitecture::kCnnLstm) {
    // The report's stack: a convolution over time (h[0] filters, kernel 5, ReLU, max-pool 2)
    // feeding an LSTM of h[1] units; its last step's output to the outputs.
    conv1 = register_module(
        "conv1", torch::nn::Conv1d(torch::nn::Conv1dOptions(n_features, h[0], 5).padding(2)));
    lstm = register_module(
        "lstm",
        torch::nn::LSTM(torch::nn::LSTMOptions(h[0], h[1]).num_layers(1).batch_first(true)));
    lstm_fc = register_module("lstm_fc", torch::nn::Linear(h[1], outputs));
  } else {
    // LSTM layers of h[0] units (h.size() layers), the last step's output to one value.
    lstm = register_module("lstm", torch::nn::LSTM(torch::nn::LSTMOptions(n_features, h[0])
                                                       .num_layers(static_cast<int64_t>(h.size()))
                                                       .batch_first(true)));
    lstm_fc = register_module("lstm_fc", torch::nn::Linear(h[0], outputs));
  }
  if (coefficients) {
    // Start from the model's own coefficients: every correction (nearly) zero. The last layer:
    // the MLP's, the CNN's second dense layer, or the LSTM's (and the CNN->LSTM's) lstm_fc.
    torch::NoGradGuard g;
    const std::shared_ptr<torch::nn::LinearImpl> last =
        architecture == NeuralArchitecture::kMlp ? mlp->ptr<torch::nn::LinearImpl>(mlp->size() - 1)
        : architecture == NeuralArchitecture::kCnn ? cnn_fc2.ptr()
                                                   : lstm_fc.ptr();
    last->weight.mul_(0.01);
    last->bias.zero_();
  }
  if (n_tl > 0 && !coefficients) {
    tl_linear = register_module("tl_linear",
                                torch::nn::Linear(torch::nn::LinearOptions(n_tl, 1).bias(false)));
    torch::NoGradGuard g;
    tl_linear->weight.zero_();  // start from the calibrated TL coefficients
  }
}

torch::Tensor CompensatorNetImpl::forward(const torch::Tensor& x, const torch::Tensor& tl) {
  torch::Tensor y;
  if (architecture == NeuralArchitecture::kMlp) {
    y = mlp->forward(x.flatten(1));
  } else if (architecture == NeuralArchitecture::kCnn) {
    torch::Tensor z = x.transpose(1, 2);  // [B, F, k]
    z = torch::max_pool1d(torch::relu(conv1->forward(z)), 2);
    z = torch::max_pool1d(torch::relu(conv2->forward(z)), 2);
    y = cnn_fc2->forward(torch::relu(cnn_fc1->forward(z.flatten(1))));
  } else if (architecture == NeuralArchitecture::kCnnLstm) {
    torch::Tensor z = x.transpose(1, 2);  // [B, F, k]
    z = torch::max_pool1d(torch::relu(conv1->forward(z)), 2).transpose(1, 2).contiguous();
    if (fused_lstm && z.scalar_type() == torch::kFloat32) {
      y = lstm_fc->forward(fused_lstm_last(z, lstm->all_weights()));
    } else {
      auto out = std::get<0>(lstm->forward(z));
      y = lstm_fc->forward(out.select(1, out.size(1) - 1));
    }
  } else if (fused_lstm && x.scalar_type() == torch::kFloat32) {
    // Training and validation (float32): one autograd node for the whole recurrence.
    y = lstm_fc->forward(fused_lstm_last(x, lstm->all_weights()));
  } else {
    auto out = std::get<0>(lstm->forward(x));
    y = lstm_fc->forward(out.select(1, out.size(1) - 1));
  }
  if (coefficients) return (y * tl).sum(1);  // A(t) δc(t), on the scaled columns
  y = y.squeeze(1);
  if (tl_linear && tl.defined()) y = y + tl_linear->forward(tl).squeeze(1);
  return y;
}

torch::Tensor CompensatorNetImpl::input_weights() {
  if (architecture == NeuralArchitecture::kMlp) {
    const torch::Tensor w = mlp->ptr<torch::nn::LinearImpl>(0)->weight;  // [h0, k F], t-major
    return w.reshape({-1, n_features});
  }
  if (architecture == NeuralArchitecture::kCnn || architecture == NeuralArchitecture::kCnnLstm)
    return conv1->weight.transpose(1, 2).reshape({-1, n_features});  // [h0, F, 5] -> [5 h0, F]
  return lstm->named_parameters()["weight_ih_l0"];                   // [4H, F]
}

void CompensatorNetImpl::zero_inputs(const torch::Tensor& columns) {
  torch::NoGradGuard g;
  if (architecture == NeuralArchitecture::kMlp) {
    torch::Tensor w = mlp->ptr<torch::nn::LinearImpl>(0)->weight;  // [h0, k F], t-major
    w.view({w.size(0), -1, n_features}).index_fill_(2, columns, 0.0);
  } else if (architecture == NeuralArchitecture::kCnn ||
             architecture == NeuralArchitecture::kCnnLstm) {
    conv1->weight.index_fill_(1, columns, 0.0);  // [h0, F, 5]
  } else {
    lstm->named_parameters()["weight_ih_l0"].index_fill_(1, columns, 0.0);  // [4H, F]
  }
}

namespace {

/// A trained network for inference, in double precision, one thread.
class TorchNetwork : public NeuralNetwork {
 public:
  TorchNetwork(const NeuralSpec& spec, int n_features)
      : net_(spec, n_features, columns_of(spec)),
        k_(spec.window),
        f_(n_features),
        p_(columns_of(spec)) {
    std::ifstream probe(spec.weights_path);
    if (!probe) throw std::runtime_error("neural weights file not found or not readable");
    // Saved with the TL layer in joint mode: load into a net that has it, then drop it (the core
    // applies tl_delta itself).
    CompensatorNet full(spec, n_features,
                        spec.mode == NeuralMode::kJoint ? static_cast<int>(spec.tl_delta.size())
                                                        : columns_of(spec));
    torch::load(full, spec.weights_path);
    auto src = full->named_parameters();
    torch::NoGradGuard g;
    for (auto& p : net_->named_parameters()) p.value().copy_(src[p.key()]);
    for (auto& b : net_->named_buffers()) b.value().copy_(full->named_buffers()[b.key()]);
    net_->to(torch::kFloat64);
    net_->eval();
    if (spec.architecture == NeuralArchitecture::kLstm) export_lstm();
  }
  void predict(const double* windows, std::int64_t count, double* out,
               const double* columns) override {
    if (p_ > 0 && !columns) throw std::runtime_error("the coefficients mode needs the columns");
    if (!lstm_.empty() && count == 1) {  // batch 1: a plain loop beats libtorch's per-step ops
      const Eigen::VectorXd y = lstm_one(windows);
      out[0] = p_ > 0 ? y.dot(Eigen::Map<const Eigen::VectorXd>(columns, p_)) : y[0];
      return;
    }
    torch::InferenceMode guard;
    const torch::Tensor x =
        torch::from_blob(const_cast<double*>(windows), {count, k_, f_}, torch::kFloat64);
    const torch::Tensor tl =
        p_ > 0 ? torch::from_blob(const_cast<double*>(columns), {count, p_}, torch::kFloat64)
               : torch::Tensor();
    const torch::Tensor y = net_->forward(x, tl).contiguous();
    std::copy(y.data_ptr<double>(), y.data_ptr<double>() + count, out);
  }

 private:
  /// One LSTM layer's weights (torch's gate order: input, forget, cell, output).
  struct LstmLayer {
    Eigen::MatrixXd w_ih, w_hh;  // [4H, in], [4H, H]
    Eigen::VectorXd bias;        // b_ih + b_hh
  };

  /// The body's outputs in coefficients mode (one per model column), else 0.
  static int columns_of(const NeuralSpec& spec) {
    return spec.mode == NeuralMode::kCoefficients ? static_cast<int>(spec.column_scale.size()) : 0;
  }

  static Eigen::MatrixXd to_eigen(const torch::Tensor& t) {
    const torch::Tensor c = t.to(torch::kFloat64).contiguous();
    const int64_t rows = c.size(0), cols = c.dim() > 1 ? c.size(1) : 1;
    Eigen::MatrixXd m(rows, cols);
    for (int64_t r = 0; r < rows; ++r)
      for (int64_t k = 0; k < cols; ++k) m(r, k) = c.data_ptr<double>()[r * cols + k];
    return m;
  }

  void export_lstm() {
    auto p = net_->named_parameters();
    for (int64_t l = 0; l < net_->lstm->options.num_layers(); ++l) {
      const std::string n = std::to_string(l);
      LstmLayer layer;
      layer.w_ih = to_eigen(p["lstm.weight_ih_l" + n]);
      layer.w_hh = to_eigen(p["lstm.weight_hh_l" + n]);
      layer.bias = to_eigen(p["lstm.bias_ih_l" + n]) + to_eigen(p["lstm.bias_hh_l" + n]);
      lstm_.push_back(std::move(layer));
    }
    fc_w_ = to_eigen(p["lstm_fc.weight"]);  // [outputs, H]
    fc_b_ = to_eigen(p["lstm_fc.bias"]).col(0);
  }

  /// The LSTM over one window [k, F] from zero state, in double precision (as torch does): its
  /// outputs (one, or one per model column).
  Eigen::VectorXd lstm_one(const double* window) const {
    const Eigen::Index hsize = lstm_[0].w_hh.cols();
    std::vector<Eigen::VectorXd> h(lstm_.size(), Eigen::VectorXd::Zero(hsize)),
        c(lstm_.size(), Eigen::VectorXd::Zero(hsize));
    Eigen::VectorXd gates(4 * hsize);
    auto sigmoid = [](const auto& x) { return (1.0 + (-x).exp()).inverse(); };
    for (std::int64_t t = 0; t < k_; ++t) {
      Eigen::VectorXd in = Eigen::Map<const Eigen::VectorXd>(window + t * f_, f_);
      for (size_t l = 0; l < lstm_.size(); ++l) {
        const LstmLayer& w = lstm_[l];
        gates.noalias() = w.w_ih * in;
        gates.noalias() += w.w_hh * h[l];
        gates += w.bias;
        const Eigen::ArrayXd i = sigmoid(gates.segment(0, hsize).array());
        const Eigen::ArrayXd f = sigmoid(gates.segment(hsize, hsize).array());
        const Eigen::ArrayXd g = gates.segment(2 * hsize, hsize).array().tanh();
        const Eigen::ArrayXd o = sigmoid(gates.segment(3 * hsize, hsize).array());
        c[l] = (f * c[l].array() + i * g).matrix();
        h[l] = (o * c[l].array().tanh()).matrix();
        in = h[l];
      }
    }
    return fc_w_ * h.back() + fc_b_;
  }

  CompensatorNet net_;
  std::int64_t k_, f_;
  std::int64_t p_;  // model columns in coefficients mode, else 0
  std::vector<LstmLayer> lstm_;
  Eigen::MatrixXd fc_w_;
  Eigen::VectorXd fc_b_;
};

}  // namespace
}  // namespace magcomp

extern "C" magcomp::NeuralNetwork* magcomp_create_network(const magcomp::NeuralSpec* spec,
                                                          int n_features, std::string* error) {
  try {
    if (n_features != static_cast<int>(spec->feature_mean.size())) {
      throw std::runtime_error("the model has " + std::to_string(spec->feature_mean.size()) +
                               " normalised features, the data gives " +
                               std::to_string(n_features));
    }
    return new magcomp::TorchNetwork(*spec, n_features);
  } catch (const std::exception& e) {
    if (error) *error = std::string("cannot load the network: ") + e.what();
    return nullptr;
  }
}
