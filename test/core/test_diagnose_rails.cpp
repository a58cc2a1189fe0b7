// diagnose and the rails (channels that record a constant and their white noise only): a drift
// their recorded wander drives is found and named; their chance fits never become candidates.
#include <gtest/gtest.h>

#include <string>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/model/term_spec.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

// random_base.yaml's flight, with a drift of the 3.3 V rail's reading (its 2 mV of recorded
// wander through a 48 s low-pass, 20,000 nT/V: 1.38 nT std over the flight) when `with_drift`.
FlightData rail_flight(bool with_drift) {
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  if (with_drift) {
    sim::HiddenEffect e;
    e.type = "drift";
    e.channel = "vol_back";
    e.time_constant_s = 48.0;
    e.gain = 20000.0;
    e.sensors = {"mag_5_uc"};
    s.hidden.push_back(e);
  }
  return sim::simulate(s, Igrf::installed()).flight;
}

DiagnoseOptions quick_options(bool search_rails) {
  DiagnoseOptions o;
  o.full_search = false;
  o.explainable_share = false;
  o.search_rails = search_rails;
  return o;
}

bool reads(const Candidate& c, const std::string& channel) {
  for (const std::string& x : term_channels(c.term))
    if (x == channel) return true;
  return false;
}

std::string rails_note(const Diagnosis& dx) {
  for (const std::string& n : dx.notes)
    if (n.find("white noise only") != std::string::npos) return n;
  return "";
}

TEST(DiagnoseRails, ADriftTheRailsRecordedWanderDrivesIsFoundAndNamed) {
  const FlightData f = rail_flight(true);
  const Model tl = test::calibrated_tl(f);
  const Diagnosis dx = diagnose(tl, f, "mag_1_c", quick_options(true));
  ASSERT_FALSE(dx.candidates.empty());
  const Candidate& top = dx.candidates.front();
  std::printf("  top %s: %.1f %% and %.1f %% of the held-out variance (baseline %.3f nT)\n",
              top.term.text().c_str(), 100 * top.explained_selection,
              100 * top.explained_confirmation, dx.baseline_std_nT);
  EXPECT_TRUE(top.accepted);
  EXPECT_EQ(top.term.text().rfind("scalar:vol_back|lp(", 0), 0u) << top.term.text();
  EXPECT_GE(top.explained_selection, kRailShare);
  EXPECT_GE(top.explained_confirmation, kRailShare);
  EXPECT_EQ(dx.verdict.rfind("add scalar:vol_back|lp(", 0), 0u) << dx.verdict;
  EXPECT_NE(rails_note(dx).find("searched only for a term explaining 25 %"), std::string::npos)
      << rails_note(dx);
  // Left out of the search, the rail names nothing and the drift stays unexplained.
  const Diagnosis without = diagnose(tl, f, "mag_1_c", quick_options(false));
  for (const Candidate& c : without.candidates) EXPECT_FALSE(reads(c, "vol_back")) << c.term;
  EXPECT_NE(rails_note(without).find("skipped"), std::string::npos) << rails_note(without);
  ASSERT_FALSE(without.candidates.empty());
  std::printf("  without the rails: top %s, %.3f nT held out against %.3f\n",
              without.candidates.front().term.text().c_str(),
              without.candidates.front().std_after_nT, top.std_after_nT);
  EXPECT_GT(without.candidates.front().std_after_nT, top.std_after_nT + 0.2);
}

TEST(DiagnoseRails, WithoutAnEffectNoRailsTermBecomesACandidate) {
  // The same flight without the drift: nine rails' slow terms fitted, none kept (a chance fit of
  // a random walk explains a few percent of a slow residual, never half of it on both splits).
  const FlightData f = rail_flight(false);
  const Model tl = test::calibrated_tl(f);
  const Diagnosis dx = diagnose(tl, f, "mag_1_c", quick_options(true));
  for (const char* rail : {"vol_back", "vol_back_p", "vol_back_n", "vol_res_p", "vol_res_n",
                           "vol_acc_p", "vol_acc_n", "vol_gyro_1", "vol_gyro_2"}) {
    EXPECT_NE(rails_note(dx).find(rail), std::string::npos) << rail << ": " << rails_note(dx);
    for (const Candidate& c : dx.candidates) EXPECT_FALSE(reads(c, rail)) << c.term;
  }
}

}  // namespace
}  // namespace magcomp
