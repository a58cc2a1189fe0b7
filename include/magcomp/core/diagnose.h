// magcomp: which physical effect is the model missing? Rank candidate terms on held-out data.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/flight_data.h"
#include "magcomp/core/model.h"

namespace magcomp {

/// One candidate effect, evaluated by adding its term to the model and refitting.
struct Candidate {
  std::string term;                 ///< exactly what `--term` accepts
  std::string effect;               ///< its physics in words
  std::string channel;              ///< the channel it uses ("" if none)
  double std_after_nT = 0.0;        ///< held-out error std (line means removed) with the term
  double explained_fraction = 0.0;  ///< 1 - (std_after / baseline)^2
  std::string estimate;             ///< fitted size in physical units, e.g. "lag 0.30 s"
};

/// Association of the held-out residual with one channel (the seed's pre-selection view).
struct ChannelAssociation {
  std::string channel;
  double pearson = 0.0;
  double spearman = 0.0;
  double mutual_information_bits = 0.0;
};

struct Diagnosis {
  double baseline_std_nT = 0.0;  ///< held-out error std of the model refitted as it is
  Eigen::Index heldout_samples = 0;
  Eigen::Index fit_samples = 0;
  std::string split;                             ///< how fit and held-out samples were chosen
  std::vector<Candidate> candidates;             ///< best first
  std::vector<ChannelAssociation> associations;  ///< strongest |Spearman| first
  std::vector<std::string> notes;                ///< skipped channels and why
};

/// Candidate term specs for this model and flight: current:/dcurrent: for every cur_* and vol_*
/// channel, rate: for the attitude rates, second_order, and the Tolles-Lawson families the model
/// lacks (diagnose adds lag:<s>, scanned).
/// Constant channels are skipped with a note.
std::vector<std::string> candidate_terms(const Model& model, const FlightData& data,
                                         std::vector<std::string>* notes);

/// Ranks the candidates. Fit samples: the model's own calibration segments when the flight holds
/// them (band-pass fit), held-out samples: every other line. Otherwise (reference fit, or no
/// calibration segment in this flight) a reference fit against `truth` on every other line,
/// held out on the rest. Throws magcomp::Error naming the file and field on bad input.
Diagnosis diagnose(const Model& model, const FlightData& data, const std::string& truth);

}  // namespace magcomp
