// magcomp: a candidate whose channel moves on one half of the held-out lines alone (see
// one_half_term.h).
#include "magcomp/core/diagnose/one_half_term.h"

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>

#include "magcomp/core/diagnose/diagnose.h"
#include "search.h"

namespace magcomp {

std::vector<int> moving_units(const Eigen::VectorXd& channel, const std::vector<int>& unit,
                              int units) {
  if (units < 2 || static_cast<size_t>(channel.size()) != unit.size()) return {};
  std::vector<double> n(static_cast<size_t>(units), 0.0), sum(n), sum2(n);
  for (size_t i = 0; i < unit.size(); ++i) {
    const int u = unit[i];
    const double v = channel[static_cast<Eigen::Index>(i)];
    if (u < 0 || u >= units || !std::isfinite(v)) continue;
    n[static_cast<size_t>(u)] += 1;
    sum[static_cast<size_t>(u)] += v;
    sum2[static_cast<size_t>(u)] += v * v;
  }
  std::vector<double> sd(static_cast<size_t>(units), NAN);
  std::vector<double> finite;
  for (size_t u = 0; u < sd.size(); ++u) {
    if (n[u] < 2) continue;
    const double mean = sum[u] / n[u];
    sd[u] = std::sqrt(std::max(sum2[u] / n[u] - mean * mean, 0.0));
    finite.push_back(sd[u]);
  }
  if (finite.size() < 2) return {};
  std::nth_element(finite.begin(), finite.begin() + static_cast<long>(finite.size() / 2),
                   finite.end());
  const double median = finite[finite.size() / 2];
  std::vector<int> out;
  for (size_t u = 0; u < sd.size(); ++u)
    if (std::isfinite(sd[u]) && sd[u] > kMovesFactor * median && sd[u] > 0)
      out.push_back(static_cast<int>(u));
  return out;
}

std::string one_half_clause(const OneHalfTerm& t) {
  if (t.term.empty()) return "";
  const char* where = t.half == 0 ? "selection" : "confirmation";
  const char* other = t.half == 0 ? "confirmation" : "selection";
  std::string lines;
  for (size_t k = 0; k < t.lines.size(); ++k) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%s%g", k ? ", " : "", t.lines[k]);
    lines += buf;
  }
  char buf[700];
  std::snprintf(buf, sizeof(buf),
                "; %s explains %.1f%% of the %s lines' error, but %s moves on the %s half's "
                "samples alone (line%s %s), not on the %s half's: this flight cannot confirm "
                "it; a second flight of the aircraft (--data A.h5,B.h5) can",
                t.term.c_str(), 100 * t.explained, where, t.channel.c_str(), where,
                t.lines.size() > 1 ? "s" : "", lines.c_str(), other);
  return buf;
}

namespace diagnose_search {

OneHalfTerm one_half_term(const FlightData& data, const Search& search,
                          const std::vector<Candidate>& candidates, double resolution_nT) {
  OneHalfTerm out;
  // A term the held-out lines accept is the verdict; nothing to say of one they cannot confirm.
  if (!candidates.empty() && candidates.front().accepted) return out;
  // Each held-out unit's half and line (a unit lies within one line and one half).
  int units = 0;
  for (int u : search.unit) units = std::max(units, u + 1);
  std::vector<int> unit_fold(static_cast<size_t>(units), -1);
  std::vector<double> unit_line(static_cast<size_t>(units), NAN);
  for (size_t i = 0; i < search.unit.size(); ++i)
    if (const int u = search.unit[i]; u >= 0) {
      unit_fold[static_cast<size_t>(u)] = search.fold[i];
      unit_line[static_cast<size_t>(u)] = search.line[static_cast<Eigen::Index>(i)];
    }
  std::map<std::string, std::vector<int>> moving;  // each channel's moving units, read once
  for (size_t k = 0, read = 0; k < candidates.size() && read < kOneHalfCandidates; ++k) {
    const Candidate& c = candidates[k];
    if (c.accepted) continue;
    ++read;
    const double shares[2] = {c.explained_selection, c.explained_confirmation};
    const int h = shares[0] >= shares[1] ? 0 : 1;
    if (!(shares[h] >= kOneHalfShare)) continue;
    // The gain on that half is above the resolution (the half's error falls by as much).
    const double before = search.base_std[h];
    if (!(before * (1 - std::sqrt(std::max(1 - shares[h], 0.0))) >= resolution_nT)) continue;
    for (const std::string& ch : term_channels(c.term)) {
      if (!data.has(ch)) continue;
      auto it = moving.find(ch);
      if (it == moving.end())
        it = moving.emplace(ch, moving_units(Eigen::VectorXd(data.column(ch)), search.unit, units))
                 .first;
      bool here = false, there = false;
      std::set<double> lines;
      for (const int u : it->second) {
        const int f = unit_fold[static_cast<size_t>(u)];
        here = here || f == h;
        there = there || f == 1 - h;
        if (f == h) lines.insert(unit_line[static_cast<size_t>(u)]);
      }
      if (!here || there) continue;
      out.term = c.term.text();
      out.channel = ch;
      out.half = h;
      out.explained = shares[h];
      out.lines.assign(lines.begin(), lines.end());
      return out;
    }
  }
  return out;
}

}  // namespace diagnose_search
}  // namespace magcomp
