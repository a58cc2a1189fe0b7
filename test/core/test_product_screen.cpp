// diagnose's product screen (screened_products): which pairs of channels are fitted as a product
// term field:x*y. A factor that steps from line to line (a battery's current decaying over the
// flight) is scored as the fits score it, each line's mean removed; and no channel takes more
// than kScreenedPerChannel of the pairs fitted.
#include <gtest/gtest.h>

#include <map>
#include <string>
#include <vector>

#include "../../src/core/diagnose/search.h"
#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/model/model.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

using diagnose_search::Job;
using diagnose_search::kScreenedPerChannel;
using diagnose_search::kScreenedProducts;
using diagnose_search::Search;

// random_base.yaml's flight with the field of a servo current scaled by the second battery's
// current (b = 3 nT/A² · x̂ · cur_bat_2 · cur_srvo_i): the battery's current decays over the
// flight (1.7 A on the calibration boxes, 0.5 A on the last line), nearly steady within a line,
// and the servo current has a mean well above its swings, so most of the product's energy on
// the held-out rows lies in its line means.
const FlightData& battery_times_servo() {
  static const FlightData f = [] {
    sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
    sim::HiddenEffect e;
    e.type = "product";
    e.channel = "cur_bat_2";
    e.channel2 = "cur_srvo_i";
    e.gain = 3.0;
    e.direction = Eigen::Vector3d(1, 0, 0);
    e.sensors = {"mag_5_uc"};
    s.hidden.push_back(e);
    return sim::simulate(s, Igrf::installed()).flight;
  }();
  return f;
}

std::vector<Job> screen(const FlightData& f, size_t keep) {
  Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  fit_model(tl, {&f});
  Diagnosis dx;
  const Search search(tl, f, "mag_1_c", &dx);
  const std::vector<std::string> sources = source_fields(tl, f, "mag_1_c", true, nullptr);
  std::vector<std::string> aircraft;
  for (const std::string& s : sources)
    if (!is_position_channel(s)) aircraft.push_back(s);
  return diagnose_search::screened_products(search, aircraft, {}, keep, 2);
}

bool names_pair(const Job& j, const std::string& a, const std::string& b) {
  const std::string t = j.term.text();
  return t == "field:" + a + "*" + b || t == "field:" + b + "*" + a;
}

TEST(ProductScreen, AFactorThatStepsBetweenLinesIsScoredWithEachLinesMeanRemoved) {
  // Scored with the product's line means in its columns' energy, the pair ranks far down (the
  // error it is scored against has each line's mean removed); scored as it is fitted, it is
  // the first pair.
  const std::vector<Job> jobs = screen(battery_times_servo(), kScreenedProducts);
  ASSERT_FALSE(jobs.empty());
  std::string fitted;
  for (const Job& j : jobs) fitted += " " + j.term.text();
  // cur_bat_1 reads the same decay (the two batteries share the load): its pair is a twin.
  const bool first = names_pair(jobs.front(), "cur_bat_2", "cur_srvo_i") ||
                     names_pair(jobs.front(), "cur_bat_1", "cur_srvo_i");
  EXPECT_TRUE(first) << fitted;
}

TEST(ProductScreen, NoChannelTakesMoreThanItsShareOfThePairsFitted) {
  // The battery's decay stands in for any slow trend: with every pair scored, it would pair with
  // most channels before the next factor; each channel reads at most kScreenedPerChannel pairs.
  const std::vector<Job> jobs = screen(battery_times_servo(), kScreenedProducts);
  ASSERT_EQ(jobs.size(), kScreenedProducts);
  std::map<std::string, size_t> reads;
  std::string fitted;
  for (const Job& j : jobs) {
    fitted += " " + j.term.text();
    for (const std::string& c : term_channels(j.term)) ++reads[c];
  }
  for (const auto& [channel, n] : reads) EXPECT_LE(n, kScreenedPerChannel) << channel << fitted;
  // Several channels beside the factors of the first pair are read.
  EXPECT_GE(reads.size(), 6u) << fitted;
}

}  // namespace
}  // namespace magcomp
