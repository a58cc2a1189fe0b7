// magcomp CLI: diagnose --apply's console output as the loop runs (diagnose_rounds_table.h).
#include "diagnose_rounds_table.h"

#include <algorithm>
#include <cstdio>

#include "common.h"

namespace magcomp::cli {

// One round of the loop on one flight, as it runs: its baseline, its first candidates, its
// verdict.
void print_round_progress(int round, size_t f, const std::vector<std::string>& paths,
                          const Diagnosis& dx, int top) {
  const size_t flights = paths.size();
  if (flights == 1)
    std::printf("== round %d\n", round);
  else
    std::printf("== round %d, flight %zu of %zu (%s)\n", round, f + 1, flights, paths[f].c_str());
  std::printf("  held-out std %.3f nT; top: %s\n", dx.baseline_std_nT,
              dx.candidates.empty() ? "(none)" : dx.candidates.front().term.text().c_str());
  for (size_t k = 0; k < dx.candidates.size() && static_cast<int>(k) < std::min(top, 5); ++k) {
    const Candidate& c = dx.candidates[k];
    std::printf("    %-34s %6.1f%% (selection %5.1f%%, confirmation %5.1f%%) %s%s\n",
                c.term.text().c_str(), 100 * c.explained_fraction, 100 * c.explained_selection,
                100 * c.explained_confirmation, c.estimate.c_str(),
                c.accepted ? "" : " [rejected]");
  }
  std::printf("  verdict: %s\n", dx.verdict.c_str());
  std::fflush(stdout);
}

// The loop's rounds: what each added (or refused, or removed), and the errors after it.
void print_rounds_table(const LoopResult& r, bool validation, size_t flights) {
  std::printf("\n%-6s %-36s %10s %14s %12s %12s%s\n", "round", "added term", "explained",
              "held-out std", "all-lines", "FOM", validation ? "   validation" : "");
  for (const auto& lr : r.rounds) {
    for (const auto& [term, why] : lr.rejected)
      std::printf("       refused %s: %s\n", term.c_str(), why.c_str());
    const std::string added = lr.round == 0              ? "(the model as given)"
                              : lr.black_box             ? "[black box] " + lr.added
                              : lr.together              ? "[together] " + lr.added
                              : lr.regularisation        ? "[ridge] " + lr.added
                              : !lr.model_change.empty() ? "[exact norm] " + lr.added
                                                         : lr.added;
    std::printf("%-6d %-36s %9.1f%% %11.3f nT %9.3f nT %9s nT", lr.round, added.c_str(),
                100 * lr.explained, lr.heldout_std_nT, lr.all_std_nT,
                figure(lr.fom_nT, "%.2f").c_str());
    if (validation) std::printf(" %9s nT", figure(lr.validation_std_nT, "%.3f").c_str());
    std::printf("\n");
    if (flights > 1) {
      std::printf("       held-out std per flight:");
      for (double v : lr.flight_heldout_std_nT) std::printf(" %s", figure(v, "%.3f").c_str());
      std::printf(" nT\n");
    }
    if (!lr.in_place_of.empty())
      std::printf(
          "       in place of %s: %.4f%% of its columns' energy lies within the model's "
          "own columns, so its gain is the ridge's hold on them, not an effect of its "
          "channel\n",
          lr.in_place_of.c_str(), 100 * lr.in_place_of_span_share);
    if (lr.together && !lr.alone_std_nT.empty()) {
      std::printf("       together: held-out %.3f nT; each alone:", lr.heldout_std_nT);
      for (double v : lr.alone_std_nT) std::printf(" %.3f", v);
      std::printf(" nT (each is needed)\n");
    }
    if (!lr.model_change.empty())
      std::printf(
          "       %s: the scalar is the norm of the Earth's field and the aircraft's; TL "
          "writes its first-order part\n",
          lr.model_change.c_str());
    if (lr.flight_halves)
      std::printf(
          "       judged with the flights as the halves (each flight's held-out lines, slow "
          "terms sized on the other flights' lines), as every round after it: no flight's own "
          "halves could confirm it; the model before it so scored %.3f nT (halves %.3f, %.3f)\n",
          lr.flight_halves_before_nT[0], lr.flight_halves_before_nT[1],
          lr.flight_halves_before_nT[2]);
    if (lr.slow_on_lines)
      std::printf(
          "       slow terms sized on the held-out lines too (fit.slow_lines): sized on the "
          "calibration rows alone, no term passed; each half scored with the size from the "
          "other half's lines\n");
    for (const auto& [term, why] : lr.removed)
      std::printf("       removed %s: %s\n", term.c_str(), why.c_str());
    for (const auto& [term, why] : lr.replaced)
      std::printf("       in place of %s: %s\n", term.c_str(), why.c_str());
    for (const auto& [term, std_nT] : lr.look_alikes)
      std::printf(
          "       look-alike %s: held-out %.3f nT in its place; these flights cannot tell its "
          "channel from %s's\n",
          term.c_str(), std_nT, lr.added.c_str());
    for (const LookAlikeRatio& q : lr.look_alike_ratios)
      std::printf(
          "       %s / %s follows %s (r %.3f), which these flights hold within %.2g %% (relative "
          "std): a flight where %s varies more tells %s from %s\n",
          q.kept_channel.c_str(), q.alike_channel.c_str(), q.channel.c_str(), q.correlation,
          100 * q.relative_std, q.channel.c_str(), q.term.c_str(), lr.added.c_str());
    if (!lr.steady_factors.empty()) {
      std::printf(
          "       %s's field may scale with a channel these flights hold steady (the term "
          "times it differs from it by less than the resolution; relative std):",
          lr.added.c_str());
      for (size_t k = 0; k < lr.steady_factors.size(); ++k)
        std::printf("%s %s %.2g %%", k ? "," : "", lr.steady_factors[k].first.c_str(),
                    100 * lr.steady_factors[k].second);
      std::printf("\n");
    }
  }
}

}  // namespace magcomp::cli
