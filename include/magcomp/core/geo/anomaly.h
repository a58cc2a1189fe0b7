// magcomp: the crustal anomaly from a total field: what the map holds.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// The anomaly, nT: a total field (compensated or raw, nT) minus the core field there (IGRF, nT)
/// and the diurnal variation (nT; 0 where the caller has none). NaN when any input is NaN. The
/// one formula the compensator node, navigation and the neural features use.
inline double anomaly_nT(double total_nT, double igrf_nT, double diurnal_nT) {
  return total_nT - igrf_nT - diurnal_nT;
}

/// The same per sample; `diurnal_nT` empty: no diurnal record (0 everywhere).
inline Eigen::VectorXd anomaly_nT(const Eigen::Ref<const Eigen::VectorXd>& total_nT,
                                  const Eigen::Ref<const Eigen::VectorXd>& igrf_nT,
                                  const Eigen::Ref<const Eigen::VectorXd>& diurnal_nT) {
  Eigen::VectorXd a(total_nT.size());
  for (Eigen::Index i = 0; i < a.size(); ++i)
    a[i] = anomaly_nT(total_nT[i], igrf_nT[i], diurnal_nT.size() ? diurnal_nT[i] : 0.0);
  return a;
}

}  // namespace magcomp
