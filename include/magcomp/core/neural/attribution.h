// magcomp: which inputs a trained neural stage leans on: permutation importance on a flight.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/math/correlation.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/neural/network.h"

namespace magcomp {

/// One input's weight in the network's prediction.
struct InputImportance {
  std::string feature;  ///< as the model's neural.features names it
  /// The rise of the network's mean squared error against its target when this input is
  /// shuffled, nT² (near 0 or below: the network does not lean on it).
  double importance_nT2 = 0.0;
  /// importance_nT2 over the sum of the positive ones (0 for an input at or below 0).
  double share = 0.0;
  /// The same rise on each line of the flight: (line number, nT²), in the lines' order.
  std::vector<std::pair<double, double>> per_line_nT2;
};

/// One recorded channel's weight: every input that reads it (the channel itself, its low-passes,
/// its products) shuffled together with one permutation.
struct ChannelImportance {
  std::string channel;                ///< a data field
  std::vector<std::string> features;  ///< the inputs that read it, in the model's order
  double importance_nT2 = 0.0;        ///< the rise of the mean squared error, nT²
  double share = 0.0;  ///< importance_nT2 over the sum of the channels' positive ones
  /// The other ranked channels whose values follow this one's on the scored samples
  /// (|r| >= kLookAlikeCorrelation), as (channel, Pearson r), the strongest first: the network
  /// cannot tell them apart, and their importance is shared between them.
  std::vector<std::pair<std::string, double>> look_alikes;
  /// A position or an earth-frame velocity (is_position_channel, is_earth_frame_velocity): where
  /// and which way the aircraft flies, never a source of its field. What the network reads from
  /// it is leakage (the map, the diurnal, TL's heading error on a flight it was not fitted on).
  bool trajectory = false;
};

/// For each of `channels`, the others whose values on `rows` of `data` correlate with it at
/// |r| >= min_abs_r (Pearson, over the rows where both are finite), as (channel, r), the
/// strongest first. A channel the data lacks, or constant on those rows, has none.
std::vector<std::vector<std::pair<std::string, double>>> look_alike_channels(
    const FlightData& data, const std::vector<std::string>& channels,
    const std::vector<Eigen::Index>& rows, double min_abs_r = kLookAlikeCorrelation);

/// A trained network's attribution on one flight.
struct Attribution {
  std::string method = "permutation importance";
  double baseline_mse_nT2 = NAN;  ///< the network's mean squared error against its target, nT²
  Eigen::Index samples = 0;       ///< the samples scored (the target finite)
  int repeats = 0;                ///< shuffles averaged per input
  int networks = 1;               ///< networks whose attributions are averaged (an ensemble)
  std::vector<InputImportance> inputs;  ///< the largest importance first
  /// The recorded channels the inputs read, the largest importance first; the model's own
  /// inputs (tl_anomaly, tl_correction, dir_*, anomaly:<field>, the vector components) are not
  /// channels of the aircraft and are left out. Where a missing effect's channel is sought.
  std::vector<ChannelImportance> channels;
  /// The model's own inputs shuffled together, nT² (NaN when it has none): above every channel's
  /// figure, what the network corrects lies in the sensors and the terms' own inputs (a lag, the
  /// terms' coefficients) rather than in a channel of the aircraft.
  double own_inputs_nT2 = NAN;
  /// The first of `channels` that is not a trajectory channel (ChannelImportance::trajectory),
  /// where a missing effect of the aircraft is sought; nullptr when there is none.
  const ChannelImportance* first_aircraft_channel() const;
};

/// Permutation importance of every input of a model's trained neural stage on `data` (a flight
/// it was not trained on, for an honest figure). Each standardised input is shuffled across the
/// scored samples (a permutation drawn from `seed`, `repeats` of them averaged), the windows are
/// rebuilt and the network run again; an input's importance is the rise of the mean squared
/// error of the network's output against its training target (neural_target: the residual of
/// the terms, or the anomaly), nT². Rows whose target is not finite are not scored. Throws
/// magcomp::Error when the model has no trained neural stage, the data lacks an input or the
/// target's reference, or no row can be scored. The same for each recorded channel, its inputs
/// shuffled together (Attribution::channels), with its look-alikes among them.
Attribution permutation_importance(const Model& model, const FlightData& data,
                                   std::shared_ptr<NeuralNetwork> network = nullptr,
                                   int repeats = 2, unsigned seed = 1);

/// The attribution of an ensemble: several networks trained on the same data with the same
/// inputs (different seeds), each attributed on the same flight. Each input's, channel's and
/// line's rise (nT²), the baselines and the model's own inputs' figure are averaged over the
/// networks, the shares recomputed and the lists ranked again. What one network leans on moves
/// with its training draw; what several lean on together is the data's. Throws magcomp::Error
/// when the list is empty or the attributions do not rank the same inputs.
Attribution average_attributions(const std::vector<Attribution>& each);

}  // namespace magcomp
