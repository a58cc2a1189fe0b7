// magcomp: the aeromagnetic figures of merit: FOM (the sum of the peak-to-peak signatures of the
// pitch, roll and yaw maneuvers flown on four headings) and the improvement ratio.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/evaluate/flight_conditions.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// One maneuver's signature: the peak-to-peak of the band-passed signal over the maneuver.
struct ManeuverSignature {
  std::string axis;     ///< pitch | roll | yaw
  std::string heading;  ///< N | E | S | W (the mean heading, 90-degree sectors)
  double start_tt_s = 0.0, end_tt_s = 0.0;
  double peak_to_peak_nT = 0.0;                ///< of the compensated signal
  double uncompensated_peak_to_peak_nT = 0.0;  ///< of the scalar as measured (realigned by the lag)
};

struct FigureOfMerit {
  std::vector<ManeuverSignature> signatures;  ///< at most 12: one per axis and heading
  double fom_nT = 0.0;                        ///< sum of the compensated signatures
  double uncompensated_fom_nT = 0.0;          ///< the same for the uncompensated scalar
  std::string where;  ///< which samples were searched (the model's calibration lines, or all)
};

/// Finds the maneuvers (classify_conditions: pitch, roll, yaw oscillations on straight legs) in
/// the samples the fit settings select (all samples when they select none), keeps the longest of
/// each axis and heading, and measures each signature on `compensated` and `uncompensated` (nT),
/// band-passed with fit.band_hz (zero-phase) over each contiguous run. Returns an empty list when
/// the flight flew no maneuver. `conditions`: classify_conditions(data) when the caller has it.
FigureOfMerit figure_of_merit(const FlightData& data, const FitSettings& fit,
                              const Eigen::Ref<const Eigen::VectorXd>& compensated,
                              const Eigen::Ref<const Eigen::VectorXd>& uncompensated,
                              const std::vector<FlightCondition>* conditions = nullptr);

/// The same windows measured on another series (e.g. the simulator's true aircraft field): the sum
/// of its band-passed peak-to-peak values, nT.
double fom_on_windows(const FlightData& data, const FitSettings& fit, const FigureOfMerit& fom,
                      const Eigen::VectorXd& series);

}  // namespace magcomp
