// magcomp: in-flight calibration.
#include "magcomp/core/fit/inflight_calibrator.h"
#include "magcomp/core/fit/model_fit.h"

#include <set>

#include "magcomp/core/error.h"

namespace magcomp {
namespace {

std::vector<const StreamSample*> pointers(const std::vector<StreamSample>& v) {
  std::vector<const StreamSample*> p;
  for (const auto& s : v) p.push_back(&s);
  return p;
}

}  // namespace

InflightCalibrator::InflightCalibrator(Model model, double forgetting)
    : model_(std::move(model)), forgetting_(forgetting) {
  if (!(forgetting_ > 0 && forgetting_ <= 1))
    throw Error("calibrator: forgetting must be in (0, 1]");
  if (model_.fit.method != FitMethod::kBandpass)
    throw Error("calibrator: in-flight fits use fit.method bandpass");
  if (!model_.slow_terms.empty())
    throw Error("calibrator: slow term '" + model_.slow_terms.front() +
                "' is fitted against a reference: calibrate it with magcomp calibrate");
  std::set<std::string> seen;
  terms_ = model_.make_terms();
  for (const auto& t : terms_) {
    if (!t->bandpass_observable())
      throw Error("calibrator: term '" + t->spec() + "' needs a reference fit");
    for (const auto& f : t->required_fields()) {
      if (seen.insert(f).second) channels_.push_back(f);
    }
  }
  if (model_.scalar_lag_s() != 0.0)
    throw Error("calibrator: lag:<s> terms are not supported in flight yet");
  reset();
}

void InflightCalibrator::reset() {
  collected_.clear();
  segment_of_.clear();
  previous_.reset();
  collected_in_segments_ = 0;
  segments_ = 0;
  in_segment_ = false;
  const Eigen::Index p = static_cast<Eigen::Index>(model_.make_column_names().size());
  theta_ = Eigen::VectorXd::Zero(p);
  p_ = Eigen::MatrixXd::Identity(p, p) / std::max(model_.fit.lambda, 1e-12);
  window_.clear();
  filters_.reset();
  segment_rows_ = rls_updates_ = 0;
}

void InflightCalibrator::end_segment() {
  in_segment_ = false;
  window_.clear();
  filters_.reset();
}

void InflightCalibrator::add(const StreamSample& s, bool in_segment) {
  if (s.channels.size() != channels_.size())
    throw Error("calibrator: sample has the wrong channel count");
  if (!in_segment) {
    if (in_segment_) {  // the sample after a segment: its edge's central difference needs it
      collected_.push_back(s);
      segment_of_.push_back(0);
      end_segment();
    }
    previous_ = std::make_unique<StreamSample>(s);
    return;
  }
  if (!in_segment_) {
    in_segment_ = true;
    ++segments_;
    if (previous_) {  // and the sample before it
      collected_.push_back(*previous_);
      segment_of_.push_back(0);
    }
  }
  collected_.push_back(s);
  segment_of_.push_back(segments_);
  ++collected_in_segments_;
  previous_ = std::make_unique<StreamSample>(s);
  rls_step(s);
}

void InflightCalibrator::rls_step(const StreamSample& s) {
  window_.push_back(s);
  if (window_.size() < 3) return;
  if (window_.size() > 3) window_.pop_front();
  // The design row of the middle sample (central differences need the newest one).
  std::vector<const StreamSample*> win;
  for (const auto& x : window_) win.push_back(&x);
  const FlightData w = samples_to_flight(model_, channels_, win);
  const Eigen::MatrixXd a = design_matrix(model_, terms_, w);
  const Eigen::Index p = a.cols();
  Eigen::VectorXd row = a.row(1).transpose();
  double y = w.column(model_.scalar)[1];
  if (!row.allFinite() || !std::isfinite(y)) return;
  if (!filters_) {
    const double dt = window_[1].t_s - window_[0].t_s;
    const Butterworth bp = Butterworth::band_pass(model_.fit.order, model_.fit.band_low_hz,
                                                  model_.fit.band_high_hz, 1.0 / dt);
    filters_ = std::make_unique<std::vector<StreamingFilter>>(static_cast<size_t>(p + 1),
                                                              StreamingFilter(bp));
    segment_rows_ = 0;
  }
  for (Eigen::Index j = 0; j < p; ++j) row[j] = (*filters_)[static_cast<size_t>(j)].step(row[j]);
  y = (*filters_)[static_cast<size_t>(p)].step(y);
  if (++segment_rows_ <= 10 * model_.fit.trim) return;  // the causal filter's start-up transient
  // Recursive least squares with forgetting.
  const Eigen::VectorXd pr = p_ * row;
  const double gain_den = forgetting_ + row.dot(pr);
  const Eigen::VectorXd k = pr / gain_den;
  theta_ += k * (y - row.dot(theta_));
  p_ = (p_ - k * pr.transpose()) / forgetting_;
  p_ = 0.5 * (p_ + p_.transpose());
  ++rls_updates_;
}

Model InflightCalibrator::batch() const {
  Model m = model_;
  m.fit.windows.clear();
  m.fit.lines.clear();
  for (int k = 1; k <= segments_; ++k) m.fit.lines.push_back(k);
  const FlightData f = samples_to_flight(model_, channels_, pointers(collected_), &segment_of_);
  fit_model(m, {&f});
  m.fit = model_.fit;  // keep the user's segment description in the saved model
  return m;
}

Model InflightCalibrator::rls() const {
  Model m = model_;
  m.coefficients = theta_;
  m.column_names = m.make_column_names();
  m.report = FitReport();
  m.report.samples = rls_updates_;
  m.report.segments = segments_;
  return m;
}

}  // namespace magcomp
