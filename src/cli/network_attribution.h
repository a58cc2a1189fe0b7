// magcomp command line: `diagnose --attribution`: the channels a trained network leans on, read
// from the attribution JSON `magcomp evaluate --explain --json` writes, and what became of them,
// printed and as JSON.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/model/model.h"

namespace magcomp::cli {

/// The recorded channels of the attribution in `path`, each with its share (0..1) of the
/// channels' importance, the largest first. Reads `evaluate --explain --json`'s file (its
/// "attribution", or each flight's under "flights": the shares averaged over the flights) or a
/// bare attribution object ({"channels": [{"channel", "share"}, ...]}). Throws magcomp::Error
/// naming the file and the field when the file is not JSON, holds no attribution, or a channel
/// entry lacks its name or a share in [0, 1].
std::vector<NetworkChannel> read_network_attribution(const std::string& path);

/// Prints what became of each channel (Diagnosis::network) under a heading ending in `after`;
/// with `final_model` (the loop), whether its terms (band-pass and slow) read the channel.
void print_network_checks(const std::vector<NetworkCheck>& network, const std::string& after,
                          const Model* final_model = nullptr);

/// The same as JSON: [{channel, share, searched, why_not, best_term, explained_selection,
/// explained_confirmation, accepted}], each with `final_terms` when `final_model` is given.
nlohmann::json network_json(const std::vector<NetworkCheck>& network,
                            const Model* final_model = nullptr);

}  // namespace magcomp::cli
