// magcomp: neural features and target.
#include "magcomp/core/neural/features.h"

#include <algorithm>
#include <cmath>

#include "magcomp/core/error.h"
#include "magcomp/core/geo/anomaly.h"
#include "magcomp/core/geo/igrf.h"

namespace magcomp {

FeaturePlan::FeaturePlan(const Model& model) {
  if (!model.neural) throw Error("model: no neural stage");
  const NeuralSpec& s = *model.neural;
  for (const auto& name : s.features) {
    Item it{Kind::kField, -1, 0, {}, nullptr};
    if (name == "tl_anomaly") {
      it.kind = Kind::kTlAnomaly;
      needs_igrf_ = true;
    } else if (name == "tl_correction") {
      it.kind = Kind::kTlCorrection;
    } else if (name == "dir_x" || name == "dir_y" || name == "dir_z") {
      it.kind = Kind::kDirection;
      it.axis = name[4] - 'x';
    } else if (name.rfind("anomaly:", 0) == 0) {
      it.kind = Kind::kAnomalyOf;
      if (name.size() <= 8) throw Error("model: neural feature 'anomaly:' needs a field name");
      it.field = field_index(name.substr(8));
      needs_igrf_ = true;
    } else if (name == model.vector + "_x" || name == model.vector + "_y" ||
               name == model.vector + "_z") {
      it.kind = Kind::kDirection;  // raw component: axis + 3 marks "not normalised"
      it.axis = 3 + (name.back() - 'x');
    } else if (is_signal_feature(name)) {
      it.kind = Kind::kSignal;
      const SignalExpr e = signal_feature(name, "model");
      for (const auto& src : e.sources) it.sources.push_back(field_index(src));
      if (!e.transforms.empty()) it.chain = std::make_unique<TransformChain>(e.transforms);
    } else {
      it.field = field_index(name);
    }
    std::vector<std::string> read;
    if (it.kind == Kind::kField) read.push_back(fields_[static_cast<size_t>(it.field)]);
    for (int k : it.sources) read.push_back(fields_[static_cast<size_t>(k)]);
    channels_.push_back(std::move(read));
    items_.push_back(std::move(it));
  }
  if (s.mode == NeuralMode::kAnomaly) needs_igrf_ = true;
  if (needs_igrf_) diurnal_field_ = field_index("diurnal");
}

int FeaturePlan::field_index(const std::string& name) {
  for (size_t k = 0; k < fields_.size(); ++k) {
    if (fields_[k] == name) return static_cast<int>(k);
  }
  fields_.push_back(name);
  return static_cast<int>(fields_.size() - 1);
}

void FeaturePlan::bind(const std::vector<std::string>& channel_names, const std::string& where) {
  bound_.assign(fields_.size(), -1);
  for (size_t k = 0; k < fields_.size(); ++k) {
    for (size_t c = 0; c < channel_names.size(); ++c) {
      if (channel_names[c] == fields_[k]) bound_[k] = static_cast<int>(c);
    }
    if (bound_[k] < 0 && static_cast<int>(k) != diurnal_field_) {
      throw Error(where + ": neural feature input '" + fields_[k] + "' is not available");
    }
  }
}

double FeaturePlan::diurnal_nT(const double* channels) const {
  if (diurnal_field_ < 0) return 0.0;
  const int c = bound_[static_cast<size_t>(diurnal_field_)];
  if (c < 0) return 0.0;
  return std::isfinite(channels[c]) ? channels[c] : 0.0;
}

void FeaturePlan::reset() {
  for (auto& it : items_)
    if (it.chain) it.chain->reset();
}

void FeaturePlan::row(double t_s, double scalar_nT, double tl_correction_nT, double igrf_nT,
                      const Eigen::Vector3d& vector_nT, const double* channels, double* out) {
  const double diurnal = diurnal_nT(channels);
  for (size_t k = 0; k < items_.size(); ++k) {
    const Item& it = items_[k];
    switch (it.kind) {
      case Kind::kField:
        out[k] = channels[bound_[static_cast<size_t>(it.field)]];
        break;
      case Kind::kTlAnomaly:
        out[k] = anomaly_nT(scalar_nT - tl_correction_nT, igrf_nT, diurnal);
        break;
      case Kind::kTlCorrection:
        out[k] = tl_correction_nT;
        break;
      case Kind::kAnomalyOf:
        out[k] = anomaly_nT(channels[bound_[static_cast<size_t>(it.field)]], igrf_nT, diurnal);
        break;
      case Kind::kDirection:
        out[k] = it.axis < 3 ? vector_nT[it.axis] / vector_nT.norm() : vector_nT[it.axis - 3];
        break;
      case Kind::kSignal: {
        double x = 1.0;
        for (int src : it.sources) x *= channels[bound_[static_cast<size_t>(src)]];
        if (!it.chain) {
          out[k] = x;
          break;
        }
        out[k] = NAN;  // causal (checked when parsed): one output per input
        it.chain->push(t_s, x, [&](double, double y) { out[k] = y; });
        break;
      }
    }
  }
}

std::vector<std::pair<std::string, std::vector<std::int64_t>>> channel_input_groups(
    const Model& model) {
  const FeaturePlan plan(model);
  std::vector<std::pair<std::string, std::vector<std::int64_t>>> groups;
  for (size_t k = 0; k < plan.feature_channels().size(); ++k) {
    for (const std::string& c : plan.feature_channels()[k]) {
      auto it =
          std::find_if(groups.begin(), groups.end(), [&](const auto& g) { return g.first == c; });
      if (it == groups.end()) it = groups.insert(groups.end(), {c, {}});
      if (it->second.empty() || it->second.back() != static_cast<std::int64_t>(k))
        it->second.push_back(static_cast<std::int64_t>(k));
    }
  }
  return groups;
}

NeuralInputs neural_inputs(const Model& model, const FlightData& data) {
  FeaturePlan plan(model);
  NeuralInputs in;
  const Eigen::Index n = data.size();
  in.scalar_nT = aligned_scalar(model, data);
  in.tl_columns = design_matrix(model, data);
  in.correction_nT = in.tl_columns * model.coefficients;
  in.igrf_nT = plan.needs_igrf() ? igrf_total_nT(data, Igrf::installed())
                                 : Eigen::VectorXd::Constant(n, NAN);
  std::vector<std::string> present;
  for (const auto& f : plan.fields()) {
    if (data.has(f)) {
      present.push_back(f);
    } else if (f != "diurnal") {
      throw Error(data.source() + ": neural feature input '" + f +
                  "' of the model is not in the data");
    }
  }
  plan.bind(present, data.source());
  Eigen::MatrixXd ch(n, static_cast<Eigen::Index>(present.size()));
  for (size_t c = 0; c < present.size(); ++c)
    ch.col(static_cast<Eigen::Index>(c)) = data.column(present[c]);
  const Eigen::MatrixXd chr = ch.transpose();  // one sample's channels contiguous
  const Eigen::Index f = static_cast<Eigen::Index>(plan.size());
  Eigen::MatrixXd feat_t(f, n);
  in.diurnal_nT.resize(n);
  const auto bx = data.column(model.vector + "_x");
  const auto by = data.column(model.vector + "_y");
  const auto bz = data.column(model.vector + "_z");
  const Eigen::VectorXd t = data.tt();
  for (Eigen::Index i = 0; i < n; ++i) {
    const double* chan = chr.col(i).data();
    plan.row(t[i], in.scalar_nT[i], in.correction_nT[i], in.igrf_nT[i],
             Eigen::Vector3d(bx[i], by[i], bz[i]), chan, feat_t.col(i).data());
    in.diurnal_nT[i] = plan.diurnal_nT(chan);
  }
  in.features = feat_t.transpose();
  return in;
}

Eigen::VectorXd neural_target(const Model& model, const FlightData& data, const NeuralInputs& in) {
  const NeuralSpec& s = *model.neural;
  if (!data.has(s.reference)) {
    throw Error(data.source() + ": neural reference field '" + s.reference + "' not in the data");
  }
  const auto ref = data.column(s.reference);
  if (s.mode == NeuralMode::kAnomaly) return anomaly_nT(ref, in.igrf_nT, in.diurnal_nT);
  return in.scalar_nT - in.correction_nT - ref;
}

void standardise_features(const NeuralSpec& spec, const double* raw, double* out) {
  const Eigen::Index f = spec.feature_mean.size();
  for (Eigen::Index k = 0; k < f; ++k) {
    const double z = (raw[k] - spec.feature_mean[k]) / spec.feature_std[k];
    out[k] = std::isfinite(z) ? z : 0.0;
  }
}

}  // namespace magcomp
