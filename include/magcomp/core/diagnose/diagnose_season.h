// magcomp: which effect is missing across several flights: each flight diagnosed on its own (its
// lines held out, one flight in memory at a time), the candidates ranked across the flights.
#pragma once

#include <string>
#include <vector>

#include "magcomp/core/diagnose/diagnose.h"

namespace magcomp {

/// One candidate effect across the flights.
struct SeasonCandidate {
  TermSpec term;        ///< as diagnosed on the flight where it explained most (--term accepts it)
  std::string shape;    ///< what is matched between flights: the term without its parameter values
  int accepted_on = 0;  ///< flights whose diagnosis accepted it
  int scored_on = 0;    ///< flights whose diagnosis scored it
  double mean_explained = 0.0;  ///< mean conservative explained share over the flights scoring it
  /// Mean share it is ranked by on the flights scoring it (Candidate::ranking_share: for a lag,
  /// with the channel term whose timing it explains).
  double mean_ranking_share = 0.0;
  std::vector<double> explained;  ///< per flight (Candidate::explained_fraction), NaN: not scored
  /// `term` is fitted by the slow stage on the flight it comes from (Candidate::slow): add it
  /// with --slow-term.
  bool slow = false;
};

struct SeasonDiagnosis {
  /// Accepted on the most flights first, then by mean ranking share (as one flight's diagnosis
  /// ranks its candidates).
  std::vector<SeasonCandidate> candidates;
  /// "add <term>: ..." when the top candidate is accepted on more than half of the flights and
  /// explains at least 5 % on them; else "structure remains ..." when a flight's diagnosis says so;
  /// else "complete ...".
  std::string verdict;
};

/// The shape of a term: a language term's expression with its parameters free (e.g.
/// field:cur_heat|lp(?)), "lag" for a lag, the spec itself otherwise.
std::string term_shape(const TermSpec& term);

/// Ranks the candidates of per-flight diagnoses of one model across the flights (in order).
SeasonDiagnosis merge_diagnoses(const std::vector<Diagnosis>& flights);

}  // namespace magcomp
