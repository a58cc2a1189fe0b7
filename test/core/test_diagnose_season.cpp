// Candidates ranked across several flights' diagnoses: terms matched by shape whatever their
// estimated parameters, counted, averaged, and the season's verdict by majority.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/diagnose/diagnose_season.h"

namespace magcomp {
namespace {

Candidate candidate(const std::string& term, double explained, bool accepted,
                    double ranking = NAN) {
  Candidate c;
  c.term = term;
  c.explained_fraction = explained;
  c.explained_selection = explained;
  c.explained_confirmation = explained;
  c.ranking_share = ranking;
  c.accepted = accepted;
  return c;
}

Candidate slow(Candidate c) {
  c.slow = true;
  return c;
}

Diagnosis flight(std::vector<Candidate> candidates, const std::string& verdict) {
  Diagnosis d;
  d.candidates = std::move(candidates);
  d.verdict = verdict;
  return d;
}

TEST(DiagnoseSeason, ShapesIgnoreParameterValues) {
  EXPECT_EQ(term_shape("field:cur_heat|lp(151)"), term_shape("field:cur_heat|lp(148.5)"));
  EXPECT_NE(term_shape("field:cur_heat|lp(151)"), term_shape("field:cur_heat|hp(151)"));
  EXPECT_EQ(term_shape("lag:0.3"), "lag");
  EXPECT_EQ(term_shape("lag:0.28"), "lag");
  EXPECT_EQ(term_shape("current:cur_strb"), term_shape("current:cur_strb"));
  EXPECT_NE(term_shape("current:cur_strb"), term_shape("current:cur_heat"));
  EXPECT_EQ(term_shape("permanent"), "permanent");
}

TEST(DiagnoseSeason, TheTermAcceptedOnMostFlightsWinsWithItsBestEstimate) {
  // Three flights: the heater's low-pass is accepted on all three (time constants 151, 148, 160
  // s; fitted by the slow stage on the second), the strobe wire on one only (though it explains
  // more there), a lag scored on two.
  const std::vector<Diagnosis> flights = {
      flight({candidate("field:cur_heat|lp(151)", 0.40, true),
              candidate("current:cur_strb", 0.70, true), candidate("lag:0.3", 0.10, false)},
             "add field:cur_heat|lp(151): ..."),
      flight({slow(candidate("field:cur_heat|lp(148)", 0.55, true)),
              candidate("current:cur_strb", 0.01, false)},
             "add field:cur_heat|lp(148): ..."),
      flight({candidate("field:cur_heat|lp(160)", 0.25, true), candidate("lag:0.25", 0.30, false)},
             "add field:cur_heat|lp(160): ...")};
  const SeasonDiagnosis s = merge_diagnoses(flights);
  ASSERT_EQ(s.candidates.size(), 3u);
  const SeasonCandidate& top = s.candidates[0];
  EXPECT_EQ(top.term, "field:cur_heat|lp(148)");  // where it explained most
  EXPECT_TRUE(top.slow);                          // and was fitted by the slow stage there
  EXPECT_EQ(top.accepted_on, 3);
  EXPECT_EQ(top.scored_on, 3);
  EXPECT_NEAR(top.mean_explained, (0.40 + 0.55 + 0.25) / 3, 1e-15);
  EXPECT_EQ(s.candidates[1].term, "current:cur_strb");
  EXPECT_EQ(s.candidates[1].accepted_on, 1);
  EXPECT_FALSE(s.candidates[1].slow);
  EXPECT_NEAR(s.candidates[1].mean_explained, (0.70 + 0.01) / 2, 1e-15);
  EXPECT_TRUE(std::isnan(s.candidates[1].explained[2]));  // not scored on the third flight
  EXPECT_EQ(s.candidates[2].shape, "lag");
  EXPECT_EQ(s.candidates[2].term, "lag:0.25");
  EXPECT_EQ(s.candidates[2].accepted_on, 0);
  EXPECT_EQ(s.verdict.rfind("add field:cur_heat|lp(148): accepted on 3 of 3 flights", 0), 0u)
      << s.verdict;
}

TEST(DiagnoseSeason, WithoutAMajorityTheVerdictSaysWhatTheFlightsFound) {
  // The wire accepted on one flight of three: no majority.
  std::vector<Diagnosis> flights = {
      flight({candidate("current:cur_strb", 0.70, true)}, "add current:cur_strb: ..."),
      flight({candidate("current:cur_strb", 0.01, false)}, "structure remains: 12% ..."),
      flight({candidate("current:cur_strb", 0.00, false)}, "complete: ...")};
  SeasonDiagnosis s = merge_diagnoses(flights);
  EXPECT_EQ(s.verdict.rfind("structure remains on 1 of 3 flights", 0), 0u) << s.verdict;
  flights[1].verdict = "complete: ...";
  s = merge_diagnoses(flights);
  EXPECT_EQ(s.verdict.rfind("complete", 0), 0u) << s.verdict;
  // Accepted on two of three, but explaining under 5 % on average: not added.
  flights = {flight({candidate("current:cur_strb", 0.04, true)}, "complete: ..."),
             flight({candidate("current:cur_strb", 0.03, true)}, "complete: ..."),
             flight({candidate("current:cur_strb", 0.00, false)}, "complete: ...")};
  s = merge_diagnoses(flights);
  EXPECT_EQ(s.candidates[0].accepted_on, 2);
  EXPECT_EQ(s.verdict.rfind("complete", 0), 0u) << s.verdict;
}

TEST(DiagnoseSeason, ALagIsRankedWithThePartnerWhoseTimingItExplains) {
  // As one flight ranks them: by the ranking share (a lag's includes its partner term).
  const std::vector<Diagnosis> flights = {
      flight({candidate("lag:0.3", 0.18, true, 0.90), candidate("current:cur_strb", 0.31, true)},
             ""),
      flight({candidate("lag:0.3", 0.44, true, 0.85), candidate("current:cur_strb", 0.25, true)},
             "")};
  const SeasonDiagnosis s = merge_diagnoses(flights);
  EXPECT_EQ(s.candidates[0].term, "lag:0.3");
  EXPECT_NEAR(s.candidates[0].mean_ranking_share, 0.875, 1e-15);
  EXPECT_NEAR(s.candidates[1].mean_ranking_share, 0.28, 1e-15);  // its selection share
}

}  // namespace
}  // namespace magcomp
