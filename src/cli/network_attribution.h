// magcomp command line: the channels a trained network leans on, read from the attribution JSON
// `magcomp evaluate --explain --json` writes, for `diagnose --attribution`.
#pragma once

#include <string>
#include <vector>

#include "magcomp/core/diagnose/diagnose.h"

namespace magcomp::cli {

/// The recorded channels of the attribution in `path`, each with its share (0..1) of the
/// channels' importance, the largest first. Reads `evaluate --explain --json`'s file (its
/// "attribution", or each flight's under "flights": the shares averaged over the flights) or a
/// bare attribution object ({"channels": [{"channel", "share"}, ...]}). Throws magcomp::Error
/// naming the file and the field when the file is not JSON, holds no attribution, or a channel
/// entry lacks its name or a share in [0, 1].
std::vector<NetworkChannel> read_network_attribution(const std::string& path);

}  // namespace magcomp::cli
