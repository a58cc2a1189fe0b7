// magcomp: a node's counters in its diagnostics: each a key and a count, the input faults among
// them summed for the status summary.
#pragma once

#include <diagnostic_updater/DiagnosticStatusWrapper.h>

#include <vector>

namespace magcomp::rosio {

/// One counter of a node: its diagnostics key, its count, and whether a non-zero count is an
/// input fault (the summary then warns, naming no key: the counts say which).
struct DiagnosticCount {
  const char* key;
  long count;
  bool fault = false;
};

/// Adds each counter to `stat` as key = count, in order; returns the sum of the faults' counts.
long add_counts(diagnostic_updater::DiagnosticStatusWrapper& stat,
                const std::vector<DiagnosticCount>& counts);

}  // namespace magcomp::rosio
