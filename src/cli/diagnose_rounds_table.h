// magcomp CLI: diagnose --apply's console output as the loop runs: each round's progress on
// each flight, and the rounds table at its end.
#pragma once

#include <string>
#include <vector>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/diagnose_loop.h"

namespace magcomp::cli {

/// One round of the loop on flight `f` of `paths`, as it runs: its held-out baseline (nT), its
/// first `top` candidates (at most 5) and its verdict, on stdout.
void print_round_progress(int round, size_t f, const std::vector<std::string>& paths,
                          const Diagnosis& dx, int top);

/// The loop's rounds on stdout: what each added, refused, removed or replaced, its look-alikes
/// and steady channels, and the errors after it (nT; the validation flight's with `validation`,
/// each flight's over `flights` > 1).
void print_rounds_table(const LoopResult& r, bool validation, size_t flights);

}  // namespace magcomp::cli
