// Several flights through the command line: calibrate on all of them, evaluate each in turn and
// pooled; each flight's numbers equal its own evaluation, the pooled ones their weighted means.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "hostile_util.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/sim/simulator.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

nlohmann::json read_json(const std::string& path) {
  std::ifstream f(path);
  return nlohmann::json::parse(f);
}

// Short simulated flights (rostest_short.yaml, one per seed) in `dir`, and a TL model calibrated
// on all of them through the command line (dir/m.yaml); returns the flights' paths.
std::vector<std::string> calibrated_flights(const std::string& dir,
                                            const std::vector<unsigned>& seeds) {
  std::vector<std::string> flights;
  std::string all;
  for (unsigned seed : seeds) {
    sim::Scenario s =
        sim::load_scenario(test::source_dir() + "/config/scenarios/rostest_short.yaml");
    s.seed = seed;
    flights.push_back(dir + "/f" + std::to_string(seed) + ".h5");
    sim::write_simulation(sim::simulate(s, Igrf::installed()), flights.back());
    all += (all.empty() ? "" : ",") + flights.back();
  }
  std::string out;
  EXPECT_EQ(test::run(test::cli() + " calibrate --data " + all + " --model " + test::source_dir() +
                          "/config/models/tl_sim.yaml --out " + dir + "/m.yaml",
                      &out),
            0)
      << out;
  return flights;
}

TEST(SeveralFlights, EvaluateTakesEachFlightInTurnAndPoolsThem) {
  const std::string dir = test::temp_dir("several_flights");
  const std::vector<std::string> flights = calibrated_flights(dir, {21u, 22u});
  const std::string both = flights[0] + "," + flights[1];
  std::string out;
  ASSERT_EQ(test::run(test::cli() + " evaluate --data " + both + " --model " + dir +
                          "/m.yaml --json " + dir + "/both.json",
                      &out),
            0)
      << out;
  EXPECT_NE(out.find("(2 flights)"), std::string::npos) << out;
  const nlohmann::json pooled = read_json(dir + "/both.json");
  ASSERT_EQ(pooled["flights"].size(), 2u);
  double n = 0, var = 0, sq = 0;
  for (size_t k = 0; k < 2; ++k) {
    ASSERT_EQ(test::run(test::cli() + " evaluate --data " + flights[k] + " --model " + dir +
                            "/m.yaml --json " + dir + "/one.json",
                        &out),
              0)
        << out;
    const nlohmann::json one = read_json(dir + "/one.json");
    const nlohmann::json& in_pool = pooled["flights"][k];
    EXPECT_EQ(in_pool["data"], flights[k]);
    EXPECT_EQ(in_pool["n"], one["n"]);
    EXPECT_EQ(in_pool["std_nT"], one["std_nT"]);
    EXPECT_EQ(in_pool["per_line"], one["per_line"]);
    const double k_n = one["n"].get<double>();
    n += k_n;
    var += std::pow(one["std_nT"].get<double>(), 2) * k_n;
    sq += std::pow(one["rmse_nT"].get<double>(), 2) * k_n;
  }
  EXPECT_EQ(pooled["n"].get<double>(), n);
  EXPECT_NEAR(pooled["std_nT"].get<double>(), std::sqrt(var / n), 1e-12);
  EXPECT_NEAR(pooled["rmse_nT"].get<double>(), std::sqrt(sq / n), 1e-12);
  // A report is one flight's.
  EXPECT_EQ(test::run(test::cli() + " evaluate --data " + both + " --model " + dir +
                          "/m.yaml --report " + dir + "/r",
                      &out),
            2)
      << out;
  EXPECT_NE(out.find("--report takes one flight"), std::string::npos) << out;
}

TEST(SeveralFlights, DiagnoseTakesEachFlightInTurnAndRanksTheSeason) {
  // Two short flights hiding the strobe wire and a 0.3 s lag: each flight's diagnosis is the one
  // it gets alone, and the season adds the lag (each flight's first choice).
  const std::string dir = test::temp_dir("several_diagnose");
  const std::vector<std::string> flights = calibrated_flights(dir, {31u, 32u});
  const std::string both = flights[0] + "," + flights[1];
  std::string out;
  ASSERT_EQ(test::run(test::cli() + " diagnose --channels-only --data " + both + " --model " + dir +
                          "/m.yaml --json " + dir + "/season.json",
                      &out),
            0)
      << out;
  const nlohmann::json season = read_json(dir + "/season.json");
  ASSERT_EQ(season["flights"].size(), 2u);
  for (size_t k = 0; k < 2; ++k) {
    ASSERT_EQ(test::run(test::cli() + " diagnose --channels-only --data " + flights[k] +
                            " --model " + dir + "/m.yaml --json " + dir + "/one.json",
                        &out),
              0)
        << out;
    const nlohmann::json one = read_json(dir + "/one.json");
    const nlohmann::json& in_season = season["flights"][k];
    EXPECT_EQ(in_season["data"], flights[k]);
    EXPECT_EQ(in_season["candidates"], one["candidates"]);
    EXPECT_EQ(in_season["verdict"], one["verdict"]);
    EXPECT_EQ(in_season["baseline_std_nT"], one["baseline_std_nT"]);
  }
  const nlohmann::json& top = season["season"]["candidates"][0];
  // The lag to the millisecond (0.3 s hidden).
  const std::string term = top["term"];
  ASSERT_EQ(term.rfind("lag:", 0), 0u) << term;
  EXPECT_NEAR(std::stod(term.substr(4)), 0.3, 0.01) << term;
  EXPECT_EQ(top["accepted_on"], 2);
  EXPECT_EQ(season["verdict"].get<std::string>().rfind("add " + term + ": accepted on 2 of 2", 0),
            0u)
      << season["verdict"];
  EXPECT_NE(out.find("verdict"), std::string::npos);
  // These two flights are of two aircraft (each seed draws its own): one model fitted on both
  // fits neither, and the loop over them says so.
  ASSERT_EQ(test::run(test::cli() + " diagnose --channels-only --apply --rounds 1 --out " + dir +
                          "/x.yaml --data " + both + " --model " + dir + "/m.yaml",
                      &out),
            0)
      << out;
  EXPECT_NE(out.find("warning: " + flights[0] + ": the model fitted on all the flights leaves"),
            std::string::npos)
      << out;
  // The loop (--apply) over two flights of one aircraft: each round diagnoses each flight, the
  // model is fitted on both, and both hidden effects are added, each flight's held-out error
  // falling with them.
  std::string one_aircraft;
  for (unsigned seed : {33u, 34u}) {
    sim::Scenario s =
        sim::load_scenario(test::source_dir() + "/config/scenarios/rostest_short.yaml");
    s.seed = seed;
    s.aircraft_seed = 7;
    const std::string path = dir + "/g" + std::to_string(seed) + ".h5";
    sim::write_simulation(sim::simulate(s, Igrf::installed()), path);
    one_aircraft += (one_aircraft.empty() ? "" : ",") + path;
  }
  ASSERT_EQ(test::run(test::cli() + " diagnose --channels-only --apply --out " + dir +
                          "/x.yaml --json " + dir + "/loop.json --data " + one_aircraft +
                          " --model " + test::source_dir() + "/config/models/tl_sim.yaml",
                      &out),
            0)
      << out;
  EXPECT_EQ(out.find("warning:"), std::string::npos) << out;
  EXPECT_NE(out.find("== round 1, flight 2 of 2"), std::string::npos) << out;
  const nlohmann::json loop = read_json(dir + "/loop.json");
  const nlohmann::json& rounds = loop["rounds"];
  ASSERT_GE(rounds.size(), 3u) << out;
  std::set<std::string> added;
  for (const auto& r : rounds) {
    ASSERT_EQ(r["flights_heldout_std_nT"].size(), 2u);
    added.insert(r["added"].get<std::string>());
  }
  const Model fitted = load_model_yaml(dir + "/x.yaml");
  bool lag = false, strobe = false;
  for (const std::string& t : fitted.terms) {
    if (t.rfind("lag:", 0) == 0) lag = std::fabs(std::stod(t.substr(4)) - 0.3) < 0.01;
    strobe = strobe || t.find("cur_strb") != std::string::npos;
  }
  EXPECT_TRUE(lag && strobe) << out;
  for (size_t f = 0; f < 2; ++f)
    EXPECT_LT(rounds.back()["flights_heldout_std_nT"][f].get<double>(),
              0.2 * rounds.front()["flights_heldout_std_nT"][f].get<double>())
        << out;
}

TEST(SeveralFlights, OneFlightGivenTwiceIsRefusedAnotherOfTheSameRouteIsNot) {
  // Two flights of one scenario (seeds 31 and 32) share their time stamps and differ in their
  // readings: calibrate takes both (calibrated_flights). The same flight named twice, by its path,
  // another spelling of it or a copy, would count its evidence twice: a term "confirmed" on a
  // second flight that is the first. Each command that learns from several flights, or checks a
  // model on another, refuses it in one line naming the option and both files, and writes nothing.
  const std::string dir = test::temp_dir("several_flights_twice");
  const std::vector<std::string> flights = calibrated_flights(dir, {31u, 32u});
  const std::string copy = dir + "/copy_of_f31.h5";
  {
    std::ifstream in(flights[0], std::ios::binary);
    std::ofstream out(copy, std::ios::binary);
    out << in.rdbuf();
  }
  const std::string model = test::source_dir() + "/config/models/tl_sim.yaml";
  const std::string out_yaml = dir + "/twice.yaml";
  test::expect_refusal(
      "calibrate --data " + flights[0] + "," + copy + " --model " + model + " --out " + out_yaml,
      {"--data: ", "copy_of_f31.h5", "f31.h5: the same time stamps and mag_5_uc",
       "give another flight"});
  test::expect_refusal("calibrate --data " + flights[0] + "," + dir + "/./f31.h5 --model " + model +
                           " --out " + out_yaml,
                       {"--data: ", "is the flight --data already gives"});
  test::expect_refusal("diagnose --data " + flights[0] + "," + copy + " --model " + dir + "/m.yaml",
                       {"--data: ", "copy_of_f31.h5"});
  test::expect_refusal("diagnose --data " + flights[0] + " --model " + model + " --apply --out " +
                           out_yaml + " --validate " + copy,
                       {"--validate: ", "copy_of_f31.h5", "is the flight --data already gives"});
  EXPECT_FALSE(test::exists(out_yaml));
}

}  // namespace
}  // namespace magcomp
