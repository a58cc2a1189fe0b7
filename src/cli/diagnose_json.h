// magcomp CLI: diagnose's JSON: a diagnosis (diagnose --json) and the loop's rounds, stop,
// added terms' support and last diagnosis (diagnose --apply --json).
#pragma once

#include <nlohmann/json.hpp>
#include <vector>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/diagnose_loop.h"
#include "magcomp/core/diagnose/term_support.h"

namespace magcomp::cli {

/// A diagnosis as diagnose --json writes it: its split, baseline (nT), candidates with their
/// shares and estimates, verdict, floor and the rest of Diagnosis.
nlohmann::json to_json(const Diagnosis& dx);
/// Each channel of a term with one it cannot be told from: [{channel, twin, correlation}].
nlohmann::json twins_json(const std::vector<ChannelTwin>& twins);
/// Each channel of a term that follows the flights' time: [{channel, share}] (share 0..1).
nlohmann::json time_trends_json(const std::vector<TimeTrend>& trends);
/// The loop's JSON: its rounds, its stop, the added terms' `support` and its last diagnosis.
nlohmann::json loop_json(const LoopResult& r, const std::vector<TermSupport>& support);

}  // namespace magcomp::cli
