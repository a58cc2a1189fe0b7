// recorded_rates: which sources another recorded source gives the rate of change of, on
// closed-form columns and on the simulator's flight, and diagnose naming such an effect by the
// recorded rate.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "magcomp/core/diagnose/channel_twins.h"
#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/recorded_rates.h"
#include "magcomp/core/math/correlation.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

// A 10 Hz flight of n rows: ins_pitch a sum of sines (deg) plus 0.02 deg of white noise;
// pitch_rate its derivative (deg/s) plus 0.05 deg/s of noise; tas a sine (m/s) plus 0.005 m/s
// of noise and lgtl_acc its derivative (m/s^2) plus 0.01 m/s^2; cur_a a random
// walk (A) and cur_b 0.9 cur_a plus noise (a twin by level, no rate); ins_roll a sine whose rate
// roll_rate misses by a slow wander of its own (not a recorded rate).
FlightData closed_form_flight(Eigen::Index n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd tt(n), pitch(n), pitch_rate(n), tas(n), acc(n), a(n), b(n), roll(n), roll_rate(n);
  double walk = 10, wander = 0;
  const double w1 = 2 * M_PI / 40, w2 = 2 * M_PI / 170, w3 = 2 * M_PI / 600;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = 0.1 * static_cast<double>(i);
    tt[i] = t;
    pitch[i] = 2 * std::sin(w1 * t) + 3 * std::sin(w2 * t + 1) + 0.02 * normal(rng);
    pitch_rate[i] = 2 * w1 * std::cos(w1 * t) + 3 * w2 * std::cos(w2 * t + 1) + 0.05 * normal(rng);
    tas[i] = 100 + 5 * std::sin(w2 * t) + 0.005 * normal(rng);
    acc[i] = 5 * w2 * std::cos(w2 * t) + 0.01 * normal(rng);
    walk += 0.05 * normal(rng);
    a[i] = walk;
    b[i] = 0.9 * walk + 0.3 * normal(rng);
    wander += 0.0002 * normal(rng);
    roll[i] = 10 * std::sin(w3 * t);
    roll_rate[i] = 10 * w3 * std::cos(w3 * t) + wander;
  }
  FlightData f;
  f.set("tt", tt);
  f.set("ins_pitch", pitch);
  f.set("pitch_rate", pitch_rate);
  f.set("tas", tas);
  f.set("lgtl_acc", acc);
  f.set("cur_a", a);
  f.set("cur_b", b);
  f.set("ins_roll", roll);
  f.set("roll_rate", roll_rate);
  return f;
}

const std::vector<std::string> kSources = {"ins_pitch", "pitch_rate", "tas",      "lgtl_acc",
                                           "cur_a",     "cur_b",      "ins_roll", "roll_rate"};

TEST(RecordedRates, AnAngleAndAnAirspeedHaveTheirRatesRecordedTwinsByLevelAndAWanderingRateDoNot) {
  const FlightData f = closed_form_flight(36000, 3);
  const std::vector<RecordedRate> rates = recorded_rates(f, kSources);
  for (const RecordedRate& r : rates)
    std::printf("  %s|d recorded as %s (r = %.5f)\n", r.channel.c_str(), r.rate.c_str(),
                r.correlation);
  ASSERT_EQ(rates.size(), 2u);
  EXPECT_EQ(rates[0].channel, "ins_pitch");
  EXPECT_EQ(rates[0].rate, "pitch_rate");
  EXPECT_EQ(rates[1].channel, "tas");
  EXPECT_EQ(rates[1].rate, "lgtl_acc");
  for (const RecordedRate& r : rates) {
    EXPECT_GE(r.correlation, kTwinCorrelation);
    EXPECT_LE(r.correlation, 1.0);
  }
  // The roll angle's rate misses roll_rate by a random walk of 0.0002 deg/s a step: their
  // 5 s means still correlate, but below the twins' |r|.
  Eigen::VectorXd d(f.size());
  const auto roll = f.column("ins_roll");
  for (Eigen::Index i = 1; i + 1 < f.size(); ++i) d[i] = (roll[i + 1] - roll[i - 1]) / 0.2;
  d[0] = d[1];
  d[f.size() - 1] = d[f.size() - 2];
  const double r = pearson(d, f.column("roll_rate"));
  std::printf("  ins_roll|d against roll_rate: r = %.5f\n", r);
  EXPECT_GT(r, 0.5);
  EXPECT_LT(r, kTwinCorrelation);
}

TEST(RecordedRates, HolesInTheAngleKeepItsRateAShortFlightNamesNone) {
  FlightData f = closed_form_flight(36000, 4);
  Eigen::VectorXd& pitch = f.mutable_column("ins_pitch");
  for (Eigen::Index i = 0; i < pitch.size(); i += 37)
    pitch[i] = std::numeric_limits<double>::quiet_NaN();
  const std::vector<RecordedRate> rates = recorded_rates(f, kSources);
  ASSERT_FALSE(rates.empty());
  EXPECT_EQ(rates[0].channel, "ins_pitch");
  EXPECT_EQ(rates[0].rate, "pitch_rate");
  // 49 blocks of 5 s: too few to tell.
  EXPECT_TRUE(recorded_rates(closed_form_flight(2450, 4), kSources).empty());
  EXPECT_FALSE(recorded_rates(closed_form_flight(2500, 4), kSources).empty());
}

TEST(RecordedRates, DiagnoseSearchesTheSimulatorsAttitudeRatesThroughTheRecordedRates) {
  // The simulator records the pitch and roll rates as the attitude's derivatives: the search
  // offers no derivative of the attitude and says why, and still offers the rates.
  const FlightData& f = test::scenario("wire_strobe").flight;
  const std::vector<RecordedRate> rates =
      recorded_rates(f, {"ins_pitch", "ins_roll", "pitch_rate", "roll_rate", "cur_strb", "tas"});
  std::set<std::pair<std::string, std::string>> pairs;
  for (const RecordedRate& r : rates) pairs.insert({r.channel, r.rate});
  EXPECT_TRUE(pairs.count({"ins_pitch", "pitch_rate"}));
  EXPECT_TRUE(pairs.count({"ins_roll", "roll_rate"}));
  EXPECT_FALSE(pairs.count({"cur_strb", "tas"}));
  const Model tl = test::calibrated_tl(f);
  DiagnoseOptions o;
  o.explainable_share = false;
  const Diagnosis dx = diagnose(tl, f, "mag_1_c", o);
  bool derivative = false, rate = false, noted = false;
  for (const Candidate& c : dx.candidates) {
    const std::string& x = c.term.text();
    if (x.find("ins_pitch|d|") != std::string::npos ||
        (x.size() >= 11 && x.compare(x.size() - 11, 11, "ins_pitch|d") == 0)) {
      std::printf("  a derivative of the pitch angle: %s\n", c.term.text().c_str());
      derivative = true;
    }
    rate = rate || c.term.text() == "rate:pitch_rate";
  }
  for (const std::string& n : dx.notes)
    noted = noted || n.find("'ins_pitch' is recorded as 'pitch_rate'") != std::string::npos;
  EXPECT_FALSE(derivative);
  EXPECT_TRUE(rate);
  EXPECT_TRUE(noted);
}

}  // namespace
}  // namespace magcomp
