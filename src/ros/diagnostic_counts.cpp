// magcomp: a node's counters in its diagnostics (diagnostic_counts.h).
#include "magcomp/ros/diagnostic_counts.h"

namespace magcomp::rosio {

long add_counts(diagnostic_updater::DiagnosticStatusWrapper& stat,
                const std::vector<DiagnosticCount>& counts) {
  long faults = 0;
  for (const DiagnosticCount& c : counts) {
    stat.add(c.key, c.count);
    if (c.fault) faults += c.count;
  }
  return faults;
}

}  // namespace magcomp::rosio
