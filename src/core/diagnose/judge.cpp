// magcomp: diagnose's judging and ranking of the candidates (see search.h).
#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <future>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

// Acceptance on both halves, then the ranking: accepted first, by their share on the selection
// lines; among the accepted within one percentage point of the best, the simplest first
// (nrml_acc before nrml_acc*vol_res_p).
void judge_and_rank(const Search& search, const DiagnoseOptions& options,
                    std::vector<Candidate>* candidates) {
  // The std a term removes on split `fold` (0 selection, 1 confirmation), nT.
  auto gain_nT = [&search](int fold, double share) {
    return search.base_std[fold] * (1 - std::sqrt(std::max(0.0, 1 - share)));
  };
  // Both splits by accept_fraction of the variance, and `fold` by the resolution; or, on a
  // quiet half (its error under kQuietHalfResolutions resolutions, where the resolution is most
  // of what is left to gain), by kQuietHalfShare of its variance while all held-out lines
  // together gain the resolution, for a term not within the base's own span (there its gain is
  // the base's: a steady voltage times the permanent columns stands in for the ridge's bias).
  auto passes = [&](const Candidate& c, int fold) {
    const double fold_share = fold == 0 ? c.explained_selection : c.explained_confirmation;
    return c.explained_selection >= options.accept_fraction &&
           c.explained_confirmation >= options.accept_fraction &&
           (gain_nT(fold, fold_share) >= options.resolution_nT ||
            (search.base_std[fold] < kQuietHalfResolutions * options.resolution_nT &&
             fold_share >= kQuietHalfShare && !(c.base_span_share >= kQuietHalfMaxSpanShare) &&
             search.base_std[2] - c.std_after_nT >= options.resolution_nT));
  };
  for (auto& c : *candidates) {
    if (!std::isfinite(c.ranking_share)) c.ranking_share = c.explained_selection;
    c.explained_fraction = std::min(c.explained_selection, c.explained_confirmation);
    c.accepted = passes(c, 0) && passes(c, 1);
  }
  std::stable_sort(candidates->begin(), candidates->end(),
                   [](const Candidate& a, const Candidate& b) {
                     if (a.accepted != b.accepted) return a.accepted;
                     return a.ranking_share > b.ranking_share;
                   });
  if (candidates->empty()) return;
  const bool none_accepted = !candidates->front().accepted;
  if (!none_accepted) {
    put_simplest_first(candidates, [](const Candidate& lead, const Candidate& c) {
      return c.accepted && c.ranking_share >= lead.ranking_share - 0.01;
    });
  }
  // The confirmation lines choose too. An effect that lives in a few lines (a current switched
  // on in some of them) may barely show on the selection lines, where a look-alike ranks first.
  // The best candidate on the confirmation lines -- lowering their error by the resolution, the
  // selection lines' by at least accept_fraction of the variance, and all held-out lines' by
  // the resolution -- takes the place of the selection lines' choice when it leaves a held-out
  // error lower by the resolution: either way a term is chosen on one half and confirmed on the
  // other. Where the selection lines accept none, only a term the slow stage sizes on the
  // held-out lines too is so chosen: a drift or a heater moves where its channel steps, a few
  // times a flight and mostly in the turns between the lines, so that one half may hold most of
  // it; cross-fitted, each half's gain is read with the size from the other half's lines, so the
  // half that holds it confirms a size it was not fitted on. Sized on the calibration rows
  // alone, where such a channel barely moves, its size does not carry over; a faster effect is
  // on every piece of every line, and a half it barely lowers speaks against it.
  const Candidate& lead = candidates->front();
  // A lag ranked with the channel term whose timing it explains is worth that pair, which its
  // own held-out error does not show: it keeps its place.
  if (!none_accepted && lead.ranking_share > lead.explained_selection) return;
  size_t pick = candidates->size();
  for (size_t k = 0; k < candidates->size(); ++k) {
    const Candidate& c = (*candidates)[k];
    if (!passes(c, 1) || search.base_std[2] - c.std_after_nT < options.resolution_nT) continue;
    if (none_accepted && !(c.slow && search.slow_cross_fitted())) continue;
    // Best on the confirmation lines; within one percentage point, the simplest.
    const Candidate* p = pick < candidates->size() ? &(*candidates)[pick] : nullptr;
    if (!p || c.explained_confirmation > p->explained_confirmation + 0.01 ||
        (c.explained_confirmation >= p->explained_confirmation - 0.01 &&
         term_complexity(c.term) < term_complexity(p->term)))
      pick = k;
  }
  if (pick == candidates->size()) return;
  if (!none_accepted && (pick == 0 || !((*candidates)[pick].std_after_nT <=
                                        lead.std_after_nT - options.resolution_nT)))
    return;
  (*candidates)[pick].accepted = true;
  (*candidates)[pick].chosen_on_confirmation = true;
  std::rotate(candidates->begin(), candidates->begin() + static_cast<long>(pick),
              candidates->begin() + static_cast<long>(pick) + 1);
}

}  // namespace magcomp::diagnose_search
