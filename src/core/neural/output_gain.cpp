// magcomp: the network's share of a hybrid model's correction (see output_gain.h).
#include "magcomp/core/neural/output_gain.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace magcomp {
namespace {

// Subtracts, from each of the vectors, its mean over the rows of each line (rows finite in all
// of them only); marks the other rows NaN.
void remove_line_means(const FlightData& f, Eigen::VectorXd* a, Eigen::VectorXd* b) {
  const Eigen::Index n = f.size();
  const Eigen::VectorXd line =
      f.has("line") ? Eigen::VectorXd(f.column("line")) : Eigen::VectorXd::Zero(n);
  std::map<double, std::pair<double, double>> sum;
  std::map<double, long> count;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!std::isfinite((*a)[i]) || !std::isfinite((*b)[i]) || !std::isfinite(line[i])) {
      (*a)[i] = (*b)[i] = NAN;
      continue;
    }
    sum[line[i]].first += (*a)[i];
    sum[line[i]].second += (*b)[i];
    ++count[line[i]];
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!std::isfinite((*a)[i])) continue;
    const auto& s = sum[line[i]];
    const double c = static_cast<double>(count[line[i]]);
    (*a)[i] -= s.first / c;
    (*b)[i] -= s.second / c;
  }
}

}  // namespace

OutputGainFit fit_output_gain(const Model& model, const std::vector<FlightData>& flights,
                              std::shared_ptr<NeuralNetwork> network) {
  OutputGainFit out;
  if (!model.neural) return out;
  Model trained = model;
  trained.neural->output_gain = 1.0;
  // Sums over the samples: e = physics error, d = the network's change of the compensated
  // value; the blended error is e + g d.
  double ee = 0, ed = 0, dd = 0, tt = 0;
  for (const FlightData& f : flights) {
    const std::string& ref = trained.neural->reference;
    if (!f.has(ref)) continue;
    const NeuralCompensation nc = neural_compensate(trained, f, network);
    const Eigen::VectorXd reference = f.column(ref);
    Eigen::VectorXd e = nc.measured_nT - nc.terms_correction_nT - reference;
    Eigen::VectorXd d = nc.terms_correction_nT - nc.correction_nT;
    remove_line_means(f, &e, &d);
    for (Eigen::Index i = 0; i < e.size(); ++i) {
      if (!std::isfinite(e[i])) continue;
      ee += e[i] * e[i];
      ed += e[i] * d[i];
      dd += d[i] * d[i];
      tt += (e[i] + d[i]) * (e[i] + d[i]);
      ++out.samples;
    }
  }
  if (out.samples == 0) return out;
  const double n = static_cast<double>(out.samples);
  out.unclipped_gain = dd > 0 ? -ed / dd : 0.0;
  out.gain = std::clamp(out.unclipped_gain, 0.0, 1.0);
  out.physics_std_nT = std::sqrt(ee / n);
  out.trained_std_nT = std::sqrt(tt / n);
  const double g = out.gain;
  out.blended_std_nT = std::sqrt(std::max(0.0, (ee + 2 * g * ed + g * g * dd) / n));
  return out;
}

}  // namespace magcomp
