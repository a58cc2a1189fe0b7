// magcomp: one sample of the inputs a model reads, as a stream delivers it, and a flight made
// of such samples (what the streaming compensator and the in-flight calibrator fit and apply on).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// The inputs at one scalar-magnetometer stamp (vector field and channels already interpolated
/// to that stamp). Times in s, fields in nT, vector in the model's vector-sensor frame.
struct StreamSample {
  double t_s = 0.0;
  double scalar_nT = 0.0;
  Eigen::Vector3d vector_nT = Eigen::Vector3d::Zero();
  std::vector<double> channels;  ///< values of required_channels(), in that order
  double igrf_nT = NAN;          ///< IGRF total field at the sample (needs_igrf() models), nT
};

/// A flight made of stream samples [begin, end): tt, the model's scalar, <vector>_x/_y/_z, the
/// channels (named `channels`, in the samples' order) and, when `lines` is given, a `line` column.
FlightData samples_to_flight(const Model& model, const std::vector<std::string>& channels,
                             const std::vector<const StreamSample*>& samples,
                             const std::vector<int>* lines = nullptr);

}  // namespace magcomp
