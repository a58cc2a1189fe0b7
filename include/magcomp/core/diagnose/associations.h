// magcomp: how a residual co-varies with each channel (the pre-selection view).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"

namespace magcomp {

/// Association of the held-out residual with one channel (the pre-selection view of Laoué,
/// "Navigation magnétique – Étalonnage en ligne de magnétomètre aéroporté", DGA).
struct ChannelAssociation {
  std::string channel;
  double pearson = 0.0;
  double spearman = 0.0;
  double mutual_information_bits = 0.0;  ///< equal-frequency bins, 16 per variable
};

/// The residual e0 (nT) at the held-out rows, each line's mean removed, against every channel of
/// the flight except the bookkeeping fields, the magnetometers and `truth_name`. Strongest
/// |Spearman| first. Uses at most 20,000 evenly spaced rows.
std::vector<ChannelAssociation> residual_associations(const FlightData& data,
                                                      const std::vector<Eigen::Index>& held,
                                                      const Eigen::VectorXd& e0,
                                                      const Eigen::VectorXd& line,
                                                      const std::string& truth_name);

}  // namespace magcomp
