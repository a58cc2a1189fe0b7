// magcomp: streaming compensation on a sliding window.
#include "magcomp/core/stream/streaming_compensator.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {

StreamingCompensator::StreamingCompensator(Model model, std::shared_ptr<NeuralNetwork> network)
    : model_(std::move(model)) {
  if (!model_.fitted()) throw Error("compensator: model not calibrated (no coefficients)");
  terms_ = model_.make_terms();
  for (const auto& t : terms_) lag_s_ += t->scalar_lag_s();
  // The sample's own fields are not channels.
  std::set<std::string> seen = {model_.scalar, model_.vector + "_x", model_.vector + "_y",
                                model_.vector + "_z"};
  for (const auto& t : terms_) {
    for (const auto& f : t->required_fields()) {
      if (seen.insert(f).second) channels_.push_back(f);
    }
  }
  // Language terms with transforms: their signals run as causal chains over the whole stream.
  std::set<std::string> streamed;
  for (const auto& t : terms_) {
    const auto* e = dynamic_cast<const ExprTerm*>(t.get());
    if (!e || e->signal().transforms.empty() || !streamed.insert(e->signal().str()).second)
      continue;
    StreamedSignal sig;
    const SignalExpr& x = e->signal();
    for (const auto& src : x.sources) {
      sig.sources.push_back(src);
      int kind = 0, index = -1;
      if (src == "B") {
        kind = 1;
      } else if (src == "Bt") {
        kind = 2;
      } else if (src == model_.scalar) {
        kind = 3;
      } else if (src == model_.vector + "_x" || src == model_.vector + "_y" ||
                 src == model_.vector + "_z") {
        kind = 4 + (src.back() - 'x');
      } else {
        index = static_cast<int>(std::find(channels_.begin(), channels_.end(), src) -
                                 channels_.begin());
      }
      sig.source_kind.push_back(kind);
      sig.source_index.push_back(index);
    }
    const int w = x.width();
    for (int c = 0; c < w; ++c) {
      sig.chains.push_back(std::make_unique<TransformChain>(x.transforms));
      sig.next_output.push_back(0);
      sig.columns.push_back(e->stream_column(c));
    }
    sig.first_column = derived_columns_;
    derived_columns_ += static_cast<size_t>(w);
    signal_lookahead_ = std::max(signal_lookahead_, x.lookahead());
    signals_.push_back(std::move(sig));
  }
  if (model_.neural && model_.neural->trained()) {
    plan_ = std::make_unique<FeaturePlan>(model_);
    for (const auto& f : plan_->fields()) {
      if (seen.insert(f).second) channels_.push_back(f);
    }
    plan_->bind(channels_, "compensator");
    if (!network) network = load_neural_network(model_, static_cast<int>(plan_->size()));
    streamer_ = std::make_unique<NeuralStreamer>(*model_.neural, std::move(network));
    feature_row_.resize(plan_->size());
  }
}

void StreamingCompensator::reset() {
  if (streamer_) streamer_->reset();
  if (plan_) plan_->reset();
  buffer_.clear();
  derived_.clear();
  for (auto& sig : signals_) {
    for (auto& c : sig.chains) c->reset();
    for (auto& n : sig.next_output) n = 0;
  }
  base_index_ = 0;
  next_ = 0;
  half_ = 0;
}

void StreamingCompensator::store_signal(size_t signal, int component, double value) {
  StreamedSignal& sig = signals_[signal];
  const long long g = sig.next_output[static_cast<size_t>(component)]++;
  const long long row = g - base_index_;
  if (row >= 0 && row < static_cast<long long>(derived_.size())) {
    derived_[static_cast<size_t>(row)][sig.first_column + static_cast<size_t>(component)] = value;
  }
}

void StreamingCompensator::feed_signals(const StreamSample& sample) {
  for (size_t k = 0; k < signals_.size(); ++k) {
    StreamedSignal& sig = signals_[k];
    const int w = static_cast<int>(sig.chains.size());
    Eigen::Vector3d x = Eigen::Vector3d::Ones();
    for (size_t j = 0; j < sig.sources.size(); ++j) {
      switch (sig.source_kind[j]) {
        case 1:
          x = x.cwiseProduct(sample.vector_nT);
          break;
        case 2:
          x *= sample.vector_nT.norm();
          break;
        case 3:
          x *= sample.scalar_nT;
          break;
        case 4:
        case 5:
        case 6:
          x *= sample.vector_nT[sig.source_kind[j] - 4];
          break;
        default:
          x *= sample.channels[static_cast<size_t>(sig.source_index[j])];
      }
    }
    for (int c = 0; c < w; ++c) {
      sig.chains[static_cast<size_t>(c)]->push(sample.t_s, x[c],
                                               [&](double, double y) { store_signal(k, c, y); });
    }
  }
}

std::vector<StreamOutput> StreamingCompensator::push(const StreamSample& sample) {
  if (sample.channels.size() != channels_.size()) {
    throw Error("compensator: sample has " + std::to_string(sample.channels.size()) +
                " channels, the model needs " + std::to_string(channels_.size()));
  }
  buffer_.push_back(sample);
  derived_.emplace_back(derived_columns_, NAN);
  feed_signals(sample);
  if (half_ == 0 && buffer_.size() >= 2) {
    const double dt = buffer_[1].t_s - buffer_[0].t_s;
    const double lag = std::abs(lag_s_);
    // Central differences need 1 neighbour; the cubic realignment by lag needs ceil(lag/dt) + 2;
    // a streamed signal's derivatives one sample each; the columns' lag round trip reads a few
    // rows each side, each with its neighbours and its streamed signals.
    const int round_trip = dt > 0 ? lag_round_trip_reach(lag_s_ / dt) : 0;
    half_ = std::max({2 + (dt > 0 ? static_cast<int>(std::ceil(lag / dt - 1e-9)) + 1 : 0),
                      signal_lookahead_ + round_trip, round_trip > 0 ? 2 + round_trip : 0});
  }
  std::vector<StreamOutput> out;
  if (half_ == 0) return out;
  while (static_cast<Eigen::Index>(buffer_.size()) - 1 - next_ >= half_) {
    out.push_back(emit(next_));
    ++next_;
  }
  // Keep `half_` samples behind the next one for its backward neighbours.
  while (next_ > half_) {
    buffer_.pop_front();
    derived_.pop_front();
    ++base_index_;
    --next_;
  }
  return out;
}

std::vector<StreamOutput> StreamingCompensator::flush() {
  for (size_t k = 0; k < signals_.size(); ++k) {  // the derivatives' last values
    for (size_t c = 0; c < signals_[k].chains.size(); ++c) {
      signals_[k].chains[c]->flush(
          [&](double, double y) { store_signal(k, static_cast<int>(c), y); });
    }
  }
  std::vector<StreamOutput> out;
  while (next_ < static_cast<Eigen::Index>(buffer_.size())) out.push_back(emit(next_++));
  reset();
  return out;
}

StreamOutput StreamingCompensator::emit(Eigen::Index index) {
  const Eigen::Index size = static_cast<Eigen::Index>(buffer_.size());
  const Eigen::Index h = std::max(half_, 2);
  const Eigen::Index first = std::max<Eigen::Index>(0, index - h);
  const Eigen::Index last = std::min(size - 1, index + h);
  std::vector<const StreamSample*> window;
  for (Eigen::Index k = first; k <= last; ++k) window.push_back(&buffer_[static_cast<size_t>(k)]);
  FlightData w = samples_to_flight(model_, channels_, window);
  for (const StreamedSignal& sig : signals_) {
    for (size_t c = 0; c < sig.columns.size(); ++c) {
      Eigen::VectorXd v(last - first + 1);
      for (Eigen::Index k = first; k <= last; ++k) {
        v[k - first] = derived_[static_cast<size_t>(k)][sig.first_column + c];
      }
      w.set(sig.columns[c], std::move(v));
    }
  }
  const Eigen::Index row = index - first;
  StreamOutput o;
  o.t_s = w.tt()[row];
  const Eigen::VectorXd aligned = aligned_scalar(model_, w, lag_s_);
  o.measured_nT = aligned[row];
  const Eigen::RowVectorXd a = design_matrix(model_, terms_, w).row(row);
  o.tl_correction_nT = a.dot(model_.coefficients);
  o.columns = a.transpose();
  o.correction_nT = o.tl_correction_nT;
  o.igrf_nT = buffer_[static_cast<size_t>(index)].igrf_nT;
  if (streamer_) {
    const StreamSample& x = buffer_[static_cast<size_t>(index)];
    const NeuralSpec& s = *model_.neural;
    plan_->row(o.t_s, o.measured_nT, o.tl_correction_nT, x.igrf_nT, x.vector_nT, x.channels.data(),
               feature_row_.data());
    const double y = streamer_->push(feature_row_.data(), a.data());
    const double delta = s.tl_delta.size() > 0 ? a.dot(s.tl_delta) : 0.0;
    o.correction_nT = neural_correction_nT(s, o.measured_nT, o.tl_correction_nT, delta, x.igrf_nT,
                                           plan_->diurnal_nT(x.channels.data()), y);
  }
  o.compensated_nT = o.measured_nT - o.correction_nT;
  o.variance_nT2 =
      streamer_ ? (model_.neural->validation_rmse_nT > 0
                       ? model_.neural->validation_rmse_nT * model_.neural->validation_rmse_nT
                       : NAN)
                : sample_variance_nT2(model_, a);
  return o;
}

}  // namespace magcomp
