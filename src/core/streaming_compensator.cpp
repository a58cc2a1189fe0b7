// magcomp: streaming compensation on a sliding window.
#include "magcomp/core/streaming_compensator.h"

#include <cmath>
#include <set>

#include "magcomp/core/error.h"

namespace magcomp {

StreamingCompensator::StreamingCompensator(Model model, std::shared_ptr<NeuralNetwork> network)
    : model_(std::move(model)) {
  if (!model_.fitted()) throw Error("compensator: model not calibrated (no coefficients)");
  terms_ = model_.make_terms();
  for (const auto& t : terms_) lag_s_ += t->scalar_lag_s();
  std::set<std::string> seen;
  for (const auto& t : terms_) {
    for (const auto& f : t->required_fields()) {
      if (seen.insert(f).second) channels_.push_back(f);
    }
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
  buffer_.clear();
  next_ = 0;
  half_ = 0;
}

std::vector<StreamOutput> StreamingCompensator::push(const StreamSample& sample) {
  if (sample.channels.size() != channels_.size()) {
    throw Error("compensator: sample has " + std::to_string(sample.channels.size()) +
                " channels, the model needs " + std::to_string(channels_.size()));
  }
  buffer_.push_back(sample);
  if (half_ == 0 && buffer_.size() >= 2) {
    const double dt = buffer_[1].t_s - buffer_[0].t_s;
    const double lag = std::abs(lag_s_);
    // Central differences need 1 neighbour; the cubic realignment by lag needs ceil(lag/dt) + 2.
    half_ = 2 + (dt > 0 ? static_cast<int>(std::ceil(lag / dt - 1e-9)) + 1 : 0);
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
    --next_;
  }
  return out;
}

std::vector<StreamOutput> StreamingCompensator::flush() {
  std::vector<StreamOutput> out;
  while (next_ < static_cast<Eigen::Index>(buffer_.size())) out.push_back(emit(next_++));
  reset();
  return out;
}

FlightData samples_to_flight(const Model& model, const std::vector<std::string>& channels,
                             const std::vector<const StreamSample*>& samples,
                             const std::vector<int>* lines) {
  const Eigen::Index n = static_cast<Eigen::Index>(samples.size());
  Eigen::VectorXd tt(n), s(n), bx(n), by(n), bz(n), l(n);
  std::vector<Eigen::VectorXd> ch(channels.size(), Eigen::VectorXd(n));
  for (Eigen::Index k = 0; k < n; ++k) {
    const StreamSample& x = *samples[static_cast<size_t>(k)];
    tt[k] = x.t_s;
    s[k] = x.scalar_nT;
    bx[k] = x.vector_nT.x();
    by[k] = x.vector_nT.y();
    bz[k] = x.vector_nT.z();
    if (lines) l[k] = (*lines)[static_cast<size_t>(k)];
    for (size_t c = 0; c < channels.size(); ++c) ch[c][k] = x.channels[c];
  }
  FlightData w;
  w.set_source("stream");
  w.set("tt", tt);
  if (lines) w.set("line", l);
  w.set(model.scalar, s);
  w.set(model.vector + "_x", bx);
  w.set(model.vector + "_y", by);
  w.set(model.vector + "_z", bz);
  for (size_t c = 0; c < channels.size(); ++c) w.set(channels[c], ch[c]);
  return w;
}

StreamOutput StreamingCompensator::emit(Eigen::Index index) {
  const Eigen::Index size = static_cast<Eigen::Index>(buffer_.size());
  const Eigen::Index h = std::max(half_, 2);
  const Eigen::Index first = std::max<Eigen::Index>(0, index - h);
  const Eigen::Index last = std::min(size - 1, index + h);
  std::vector<const StreamSample*> window;
  for (Eigen::Index k = first; k <= last; ++k) window.push_back(&buffer_[static_cast<size_t>(k)]);
  const FlightData w = samples_to_flight(model_, channels_, window);
  const Eigen::Index row = index - first;
  StreamOutput o;
  o.t_s = w.tt()[row];
  const Eigen::VectorXd aligned = aligned_scalar(model_, w, lag_s_);
  o.measured_nT = aligned[row];
  const Eigen::RowVectorXd a = design_matrix(model_, terms_, w).row(row);
  o.tl_correction_nT = a.dot(model_.coefficients);
  o.correction_nT = o.tl_correction_nT;
  o.igrf_nT = buffer_[static_cast<size_t>(index)].igrf_nT;
  if (streamer_) {
    const StreamSample& x = buffer_[static_cast<size_t>(index)];
    const NeuralSpec& s = *model_.neural;
    plan_->row(o.measured_nT, o.tl_correction_nT, x.igrf_nT, x.vector_nT, x.channels.data(),
               feature_row_.data());
    const double y = streamer_->push(feature_row_.data());
    const double delta = s.tl_delta.size() > 0 ? a.dot(s.tl_delta) : 0.0;
    o.correction_nT = neural_correction_nT(s, o.measured_nT, o.tl_correction_nT, delta, x.igrf_nT,
                                           plan_->diurnal_nT(x.channels.data()), y);
  }
  o.compensated_nT = o.measured_nT - o.correction_nT;
  return o;
}

}  // namespace magcomp
