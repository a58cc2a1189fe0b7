// The command line's contract (the JSON keys checked outside this repository): calibrate then
// evaluate on a synthetic flight with known coefficients, diagnose and its loop (--apply) on a
// simulated hidden effect; bad input gives one line naming the file, field or term.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/sim/simulator.h"
#include "scenario_cache.h"
#include "synthetic_flight.h"
#include "test_util.h"

namespace magcomp {
namespace {

TEST(Cli, CalibrateThenEvaluateWritesTheContractJson) {
  const std::string dir = test::temp_dir("cli");
  const Model m = test::tl16_model();
  const FlightData d = test::synthetic_tl_flight(m, test::known_coefficients(16));
  write_flight_h5(d, dir + "/flight.h5");
  std::ofstream(dir + "/model.yaml") << "scalar: mag_5_uc\nvector: flux_c\n"
                                        "terms: [permanent, induced5]\n"
                                        "fit:\n  method: bandpass\n  lines: [1000.01, 1001.01]\n"
                                        "  lambda: 1.0e-9\n";
  std::string out;
  ASSERT_EQ(test::run(test::cli() + " calibrate --data " + dir + "/flight.h5 --model " + dir +
                          "/model.yaml --term eddy8 --out " + dir + "/fitted.yaml",
                      &out),
            0)
      << out;
  EXPECT_NE(out.find("16 coefficients"), std::string::npos) << out;
  ASSERT_EQ(test::run(test::cli() + " evaluate --data " + dir + "/flight.h5 --model " + dir +
                          "/fitted.yaml --truth mag_1_c --json " + dir + "/e.json",
                      &out),
            0)
      << out;
  nlohmann::json j;
  std::ifstream(dir + "/e.json") >> j;
  EXPECT_LT(j["std_nT"].get<double>(), 1e-3);
  ASSERT_EQ(j["per_line"].size(), 4u);
  EXPECT_EQ(j["per_line"][0]["n"].get<int>(), 1500);
  EXPECT_TRUE(j["per_line"][0].contains("rmse_nT"));
  EXPECT_TRUE(j.contains("rmse_nT"));

  // Failures: one line naming the file / field / parameter, non-zero exit.
  EXPECT_NE(test::run(test::cli() + " evaluate --data " + dir + "/flight.h5 --model " + dir +
                          "/fitted.yaml --truth mag_9_c",
                      &out),
            0);
  EXPECT_NE(out.find("'mag_9_c'"), std::string::npos) << out;
  EXPECT_NE(test::run(test::cli() + " calibrate --data " + dir + "/flight.h5 --model " + dir +
                          "/model.yaml --term current:cur_nope --out " + dir + "/x.yaml",
                      &out),
            0);
  EXPECT_NE(out.find("cur_nope"), std::string::npos) << out;
  EXPECT_NE(test::run(test::cli() + " calibrate --data " + dir + "/nothere.h5 --model " + dir +
                          "/model.yaml --out " + dir + "/x.yaml",
                      &out),
            0);
  EXPECT_NE(out.find("nothere.h5"), std::string::npos) << out;
  std::ofstream(dir + "/empty.yaml") << "scalar: mag_5_uc\nvector: flux_c\n"
                                        "fit: {lines: [7777.0]}\n";
  EXPECT_NE(test::run(test::cli() + " calibrate --data " + dir + "/flight.h5 --model " + dir +
                          "/empty.yaml --out " + dir + "/x.yaml",
                      &out),
            0);
  EXPECT_NE(out.find("no usable sample"), std::string::npos) << out;
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
}

TEST(Cli, DiagnoseWritesTheContractJsonAndTheLoop) {
  const std::string dir = test::temp_dir("dx");
  sim::write_simulation(test::scenario("inductive_heater"), dir + "/f.h5");
  std::string out;
  ASSERT_EQ(
      test::run(test::cli() + " calibrate --data " + dir + "/f.h5 --model " + test::source_dir() +
                    "/config/models/tl_sim.yaml --out " + dir + "/m.yaml",
                &out),
      0)
      << out;
  ASSERT_EQ(test::run(test::cli() + " diagnose --data " + dir + "/f.h5 --model " + dir +
                          "/m.yaml --json " + dir + "/d.json",
                      &out),
            0)
      << out;
  EXPECT_NE(out.find("--term 'dcurrent:cur_heat'"), std::string::npos) << out;
  nlohmann::json j;
  std::ifstream(dir + "/d.json") >> j;
  EXPECT_GT(j["baseline_std_nT"].get<double>(), 1.0);
  const auto& top = j["candidates"][0];
  EXPECT_EQ(top["term"], "dcurrent:cur_heat");
  EXPECT_EQ(top["channel"], "cur_heat");
  EXPECT_TRUE(top["effect"].is_string());
  EXPECT_LT(top["std_after_nT"].get<double>(), 0.5);
  EXPECT_GT(top["explained_fraction"].get<double>(), 0.9);
  EXPECT_TRUE(top["accepted"].get<bool>());
  EXPECT_FALSE(top["slow"].get<bool>());
  // The pickup shows on every line: the selection lines choose it.
  EXPECT_FALSE(top["chosen_on_confirmation"].get<bool>());
  EXPECT_TRUE(top["parameters"].is_object());
  EXPECT_GT(top["parameters"]["gain_nT_per_unit"].get<double>(), 0.0);
  // A heater's wire switched on and off adds a direction of its own to TL's columns.
  ASSERT_TRUE(top["base_span_share"].is_number());
  EXPECT_GE(top["base_span_share"].get<double>(), 0.0);
  EXPECT_LT(top["base_span_share"].get<double>(), 0.9);
  EXPECT_TRUE(j["explainable_share"]["share"].is_number());
  EXPECT_TRUE(j["explainable_share"]["within_noise"].is_boolean());
  // Rejected candidates come after every accepted one.
  bool seen_rejected = false;
  for (const auto& c : j["candidates"]) {
    if (!c["accepted"].get<bool>()) seen_rejected = true;
    EXPECT_FALSE(seen_rejected && c["accepted"].get<bool>()) << c["term"];
  }
  // The loop as a command: it adds the term, refits and writes the final model. It reads a
  // network's attribution (as evaluate --explain --json writes it, over two flights), searches
  // and judges the channels it leans on, and says whether its final model names them.
  std::ofstream(dir + "/att.json")
      << R"({"flights": [{"attribution": {"channels": [{"channel": "cur_heat", "share": 0.7},
           {"channel": "cur_ac_lo", "share": 0.2}, {"channel": "lon", "share": 0.1}]}},
           {"attribution": {"channels": [{"channel": "cur_heat", "share": 0.5},
           {"channel": "cur_ac_lo", "share": 0.3}, {"channel": "lon", "share": 0.2}]}}]})";
  ASSERT_EQ(test::run(test::cli() + " diagnose --apply --data " + dir + "/f.h5 --model " + dir +
                          "/m.yaml --attribution " + dir + "/att.json --out " + dir +
                          "/final.yaml --json " + dir + "/loop.json",
                      &out),
            0)
      << out;
  EXPECT_NE(out.find("dcurrent:cur_heat"), std::string::npos) << out;
  EXPECT_NE(out.find("the network leans on (--attribution)"), std::string::npos) << out;
  EXPECT_NE(out.find("cur_heat        60 %: the final model names it (dcurrent:cur_heat"),
            std::string::npos)
      << out;
  const Model final_model = load_model_yaml(dir + "/final.yaml");
  EXPECT_TRUE(final_model.fitted());
  EXPECT_NE(std::find(final_model.terms.begin(), final_model.terms.end(), "dcurrent:cur_heat"),
            final_model.terms.end());
  nlohmann::json loop;
  std::ifstream(dir + "/loop.json") >> loop;
  ASSERT_GE(loop["rounds"].size(), 2u);
  EXPECT_LT(loop["rounds"].back()["heldout_std_nT"].get<double>(),
            0.2 * loop["rounds"][0]["heldout_std_nT"].get<double>());
  // Each round says whether it added terms together and what it removed; the support lists
  // every added term with its channel's switches and its size.
  for (const auto& round : loop["rounds"]) {
    EXPECT_TRUE(round["together"].is_boolean());
    EXPECT_TRUE(round["removed"].is_array());
    EXPECT_TRUE(round["regularisation"].is_boolean());
    EXPECT_TRUE(round["model_change"].is_string());
    EXPECT_TRUE(round["in_place_of"].is_string());
    EXPECT_GT(round["lambda"].get<double>(), 0.0);
  }
  ASSERT_TRUE(loop["support"].is_array());
  bool heater = false;
  for (const auto& s : loop["support"]) {
    if (s["term"] != "dcurrent:cur_heat") continue;
    heater = true;
    EXPECT_EQ(s["channel"], "cur_heat");
    EXPECT_GT(s["switches"].get<int>(), 0);
    EXPECT_GT(s["size_nT"].get<double>(), 0.0);
    // No low-pass: not a drift at the longest time constant the flight tells apart.
    EXPECT_TRUE(s["slowest_time_constant_s"].is_null()) << s.dump();
    EXPECT_EQ(s["slow_edge_note"], "");
    // A thermostat's current switches: it follows no curve of time.
    EXPECT_EQ(s["time_trends"], nlohmann::json::array()) << s.dump();
    EXPECT_EQ(s["time_trend_note"], "");
  }
  EXPECT_TRUE(heater) << loop["support"].dump();
  // The network's channels: the heater's named by the final model, the load's searched, the
  // position never a term.
  nlohmann::json& net = loop;
  ASSERT_EQ(net["network"].size(), 3u) << net["network"].dump();
  EXPECT_EQ(net["network"][0]["channel"], "cur_heat");
  EXPECT_NEAR(net["network"][0]["share"].get<double>(), 0.6, 1e-12);
  EXPECT_EQ(net["network"][0]["final_terms"], nlohmann::json::array({"dcurrent:cur_heat"}));
  EXPECT_EQ(net["network"][1]["channel"], "cur_ac_lo");
  EXPECT_TRUE(net["network"][1]["searched"].get<bool>());
  EXPECT_EQ(net["network"][2]["channel"], "lon");
  EXPECT_FALSE(net["network"][2]["searched"].get<bool>());
  EXPECT_NE(net["network"][2]["why_not"].get<std::string>().find("position"), std::string::npos);
  EXPECT_TRUE(net["network"][2]["final_terms"].empty());
  bool shares = false;
  for (const auto& c : net["last_diagnosis"]["candidates"])
    shares = shares || c["network_share"].get<double>() > 0;
  EXPECT_TRUE(shares);
}

}  // namespace
}  // namespace magcomp
