// magcomp: candidates ranked across several flights' diagnoses.
#include "magcomp/core/diagnose/diagnose_season.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "magcomp/core/model/terms_expr.h"

namespace magcomp {

std::string term_shape(const TermSpec& term) {
  if (term.text().rfind("lag:", 0) == 0) return "lag";
  if (const ExprTerm* e = term.expr()) return e->shape();
  return term.text();
}

SeasonDiagnosis merge_diagnoses(const std::vector<Diagnosis>& flights) {
  SeasonDiagnosis out;
  const size_t n = flights.size();
  std::map<std::string, size_t> index;  // shape -> candidate
  std::vector<double> best;             // the explained share of each candidate's `term`
  std::vector<double> ranking;          // the sum of each candidate's ranking shares
  for (size_t f = 0; f < n; ++f) {
    for (const Candidate& c : flights[f].candidates) {
      const std::string shape = term_shape(c.term);
      auto [it, fresh] = index.emplace(shape, out.candidates.size());
      if (fresh) {
        SeasonCandidate s;
        s.term = c.term;
        s.slow = c.slow;
        s.shape = shape;
        s.explained.assign(n, NAN);
        out.candidates.push_back(s);
        best.push_back(-INFINITY);
        ranking.push_back(0.0);
      }
      SeasonCandidate& s = out.candidates[it->second];
      if (std::isfinite(s.explained[f])) continue;  // a flight scores a shape once
      s.explained[f] = c.explained_fraction;
      ranking[it->second] +=
          std::isfinite(c.ranking_share) ? c.ranking_share : c.explained_selection;
      s.scored_on++;
      s.accepted_on += c.accepted;
      if (c.explained_fraction > best[it->second]) {
        best[it->second] = c.explained_fraction;
        s.term = c.term;
        s.slow = c.slow;
      }
    }
  }
  for (size_t k = 0; k < out.candidates.size(); ++k) {
    SeasonCandidate& s = out.candidates[k];
    double sum = 0;
    for (double e : s.explained) sum += std::isfinite(e) ? e : 0.0;
    s.mean_explained = s.scored_on > 0 ? sum / s.scored_on : 0.0;
    s.mean_ranking_share = s.scored_on > 0 ? ranking[k] / s.scored_on : 0.0;
  }
  std::stable_sort(out.candidates.begin(), out.candidates.end(),
                   [](const SeasonCandidate& a, const SeasonCandidate& b) {
                     if (a.accepted_on != b.accepted_on) return a.accepted_on > b.accepted_on;
                     return a.mean_ranking_share > b.mean_ranking_share;
                   });
  // Among the terms accepted on as many flights and within one percentage point of the best,
  // the simplest first (current:cur_strb before field:cur_strb|sat(5.31)), as on one flight.
  put_simplest_first(&out.candidates, [](const SeasonCandidate& lead, const SeasonCandidate& c) {
    return c.accepted_on == lead.accepted_on &&
           c.mean_ranking_share >= lead.mean_ranking_share - 0.01;
  });
  char buf[512];
  if (!out.candidates.empty()) {
    const SeasonCandidate& top = out.candidates.front();
    if (2 * top.accepted_on > static_cast<int>(n) && top.mean_explained >= 0.05) {
      std::snprintf(buf, sizeof(buf),
                    "add %s: accepted on %d of %zu flights, explaining %.1f%% of their held-out "
                    "error on average",
                    top.term.text().c_str(), top.accepted_on, n, 100 * top.mean_explained);
      out.verdict = buf;
      return out;
    }
  }
  int structure = 0;
  for (const Diagnosis& d : flights) structure += d.verdict.rfind("structure remains", 0) == 0;
  if (structure > 0) {
    std::snprintf(buf, sizeof(buf),
                  "structure remains on %d of %zu flights, and no term is accepted on more than "
                  "half of them",
                  structure, n);
  } else {
    std::snprintf(buf, sizeof(buf),
                  "complete: no term is accepted on more than half of the %zu flights, and none "
                  "finds structure left",
                  n);
  }
  out.verdict = buf;
  return out;
}

}  // namespace magcomp
