// magcomp command line: a trained network's attribution (which inputs it leans on) as the
// terminal and the JSON show it; `evaluate --explain` and `train` print it.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "magcomp/core/neural/attribution.h"

namespace magcomp::cli {

/// The table: each input's rise of the network's mean squared error when shuffled (nT²) and its
/// share, the largest first, on the flight `where` names ("this flight", a file name).
void print_attribution(const Attribution& a, const std::string& where = "this flight");

/// The JSON object: method, baseline_mse_nT2, samples, repeats, networks, inputs [{feature,
/// importance_nT2, share, per_line [{line, importance_nT2}]}].
nlohmann::json attribution_json(const Attribution& a);

}  // namespace magcomp::cli
