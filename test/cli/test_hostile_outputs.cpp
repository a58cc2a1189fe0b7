// Hostile input through the command line, the outputs' side: a figure is printed or written only
// when it is finite and stands on enough samples; no output is ever an input (by path, by another
// spelling, by hard link) or another output; nothing is written before every output is checked;
// pipes are refused where they would block; random draws are bounded.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <limits>

#include "hostile_util.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/output_guard.h"

namespace magcomp {
namespace {

using test::exists;
using test::expect_refusal;
using test::files;
using test::flight_with;
using test::slurp;

std::string fitted_model() { return files().fitted; }

TEST(HostileOutputs, FiguresFromTooFewSamplesAreRefused) {
  const FlightData f = read_flight_h5(files().flight);
  // One sample: a flight of its first row.
  FlightData one;
  for (const std::string& name : f.names()) one.set(name, Eigen::VectorXd(f.column(name)).head(1));
  write_flight_h5(one, files().dir + "/one_sample.h5");
  expect_refusal("evaluate --data " + files().dir + "/one_sample.h5 --model " + fitted_model(),
                 {"one_sample.h5", "1 finite sample(s) in 1 line(s)", "nothing to score"});
  // Every sample its own line: no spread left once each line's mean is removed.
  Eigen::VectorXd line(f.size());
  for (Eigen::Index i = 0; i < f.size(); ++i) line[i] = static_cast<double>(i);
  expect_refusal(
      "evaluate --data " + flight_with("own_lines.h5", "line", line) + " --model " + fitted_model(),
      {"own_lines.h5", "0 degree(s) of freedom", "nothing to score"});
  // A line of one sample among others: its std is n/a, the flight is scored.
  Eigen::VectorXd lines = f.column("line");
  lines[f.size() / 2] = 9999;
  std::string out;
  ASSERT_EQ(
      test::run(test::cli() + " evaluate --data " + flight_with("one_line.h5", "line", lines) +
                    " --model " + fitted_model() + " --json " + files().dir + "/one_line.json",
                &out),
      0)
      << out;
  EXPECT_NE(out.find("9999.00           1"), std::string::npos) << out;
  EXPECT_FALSE(test::prints_nan(out)) << out;
  EXPECT_NE(slurp(files().dir + "/one_line.json").find("\"std_nT\": null"), std::string::npos);
  // An empty list of flights.
  expect_refusal("evaluate --data , --model " + fitted_model(), {"--data", "no file given"});
  expect_refusal(
      "calibrate --data , --model " + files().model + " --out " + files().dir + "/x.yaml",
      {"--data", "no file given"});
  EXPECT_FALSE(exists(files().dir + "/x.yaml"));
}

TEST(HostileOutputs, ValuesNoMagnetometerGivesAreRefusedByFieldAndSample) {
  const FlightData f = read_flight_h5(files().flight);
  Eigen::VectorXd huge = f.column("mag_5_uc");
  huge[123] = 1e300;
  const std::string p = flight_with("huge_scalar.h5", "mag_5_uc", huge);
  const std::string out = files().dir + "/never.yaml";
  for (const std::string& cmd :
       {"evaluate --data " + p + " --model " + fitted_model(),
        "diagnose --data " + p + " --model " + fitted_model() + " --channels-only"})
    expect_refusal(cmd,
                   {"huge_scalar.h5", "field 'mag_5_uc'", "sample 123", "beyond any magnetic"});
  // A whole scalar scaled by 1e150: squares stay finite, the figures would be absurd. The fit
  // reads its calibration segments only, and refuses at the first of their rows.
  const std::string q =
      flight_with("scaled_scalar.h5", "mag_5_uc", Eigen::VectorXd(f.column("mag_5_uc")) * 1e150);
  expect_refusal("calibrate --data " + q + " --model " + files().model + " --out " + out,
                 {"scaled_scalar.h5", "field 'mag_5_uc'", "beyond any magnetic"});
  Eigen::VectorXd flux = f.column("flux_c_z");
  flux[7] = -std::numeric_limits<double>::infinity();
  expect_refusal("evaluate --data " + flight_with("inf_flux.h5", "flux_c_z", flux) + " --model " +
                     fitted_model(),
                 {"inf_flux.h5", "field 'flux_c_z'", "sample 7"});
  EXPECT_FALSE(exists(out));
}

TEST(HostileOutputs, AChannelOfOddValuesIsNeverAdvised) {
  // A current with values far beyond any instrument's: a candidate on it fits NaN or nothing,
  // and is never shown as explaining the error.
  const FlightData f = read_flight_h5(files().flight);
  Eigen::VectorXd flap = f.column("cur_flap");
  for (Eigen::Index i = 0; i < flap.size(); i += 7) flap[i] = 1e200;
  std::string out;
  ASSERT_EQ(test::run(test::cli() + " diagnose --data " +
                          flight_with("odd_flap.h5", "cur_flap", flap) + " --model " +
                          fitted_model() + " --channels-only --json " + files().dir + "/odd.json",
                      &out),
            0)
      << out;
  EXPECT_FALSE(test::prints_nan(out)) << out;
  const std::string j = slurp(files().dir + "/odd.json");
  EXPECT_EQ(j.find("null"), std::string::npos);
  std::istringstream lines(out);
  for (std::string line; std::getline(lines, line);) {
    if (line.find("cur_flap") != std::string::npos && line.find("[rejected") == std::string::npos) {
      EXPECT_EQ(line.find("100.0%"), std::string::npos) << line;
    }
  }
}

TEST(HostileOutputs, NoOutputIsAnInputOrAnotherOutput) {
  const std::string dir = files().dir;
  const std::string model = dir + "/guard_model.yaml";
  std::ofstream(model) << slurp(fitted_model());
  const std::string flight = dir + "/guard_flight.h5", other = dir + "/guard_other.h5";
  std::ofstream(flight, std::ios::binary) << slurp(files().flight);
  std::ofstream(other, std::ios::binary) << slurp(files().flight);
  const std::string hard = dir + "/guard_hard.h5";
  ASSERT_EQ(::link(flight.c_str(), hard.c_str()), 0);
  const std::string model_before = slurp(model), flight_before = slurp(flight),
                    other_before = slurp(other);
  const std::string apply =
      "diagnose --apply --channels-only --data " + flight + " --model " + model;
  // calibrate over its own model, under two spellings.
  expect_refusal("calibrate --data " + flight + " --model " + model + " --out " + model,
                 {"--out", "guard_model.yaml", "is an input of this command (--model"});
  expect_refusal(
      "calibrate --data " + flight + " --model " + model + " --out " + dir + "/./guard_model.yaml",
      {"is an input of this command (--model"});
  // diagnose --apply --out over the flight, the model, the validation flight, a hard link.
  expect_refusal(apply + " --out " + flight, {"--out", "(--data"});
  expect_refusal(apply + " --out " + model, {"--out", "(--model"});
  expect_refusal(apply + " --validate " + other + " --out " + other, {"--out", "(--validate"});
  expect_refusal(apply + " --out " + hard, {"--out", "guard_hard.h5", "another name"});
  // --json over the validation flight, over --out, over --data: refused before --out is written.
  const std::string out = dir + "/guard_out.yaml";
  expect_refusal(apply + " --validate " + other + " --out " + out + " --json " + other,
                 {"--json", "(--validate"});
  expect_refusal(apply + " --out " + out + " --json " + out,
                 {"--json", "is also the output --out"});
  expect_refusal(apply + " --out " + out + " --json " + flight, {"--json", "(--data"});
  EXPECT_FALSE(exists(out));
  // evaluate's and navigate's report files are outputs too.
  expect_refusal("evaluate --data " + flight + " --model " + model + " --report " + dir +
                     " --json " + dir + "/evaluation.json",
                 {"evaluation.json", "two outputs cannot share a file"});
  EXPECT_EQ(slurp(model), model_before);
  EXPECT_EQ(slurp(flight), flight_before);
  EXPECT_EQ(slurp(other), other_before);
}

TEST(HostileOutputs, AnInputChangedWhileReadIsReportedNotUsed) {
  const std::string dir = test::temp_dir("guard_change");
  const std::string in = dir + "/in.yaml";
  std::ofstream(in) << "a: 1\n";
  OutputGuard guard({{"--model", in}});
  guard.add_output("--out", dir + "/out.yaml");
  EXPECT_NO_THROW(guard.check_inputs_unchanged());
  // Another program writes into the input (same size: the modification time tells).
  ::usleep(20000);
  std::ofstream(in) << "b: 2\n";
  try {
    guard.check_inputs_unchanged();
    ADD_FAILURE() << "a changed input was not noticed";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("in.yaml (--model): changed while it was read"),
              std::string::npos)
        << e.what();
  }
}

TEST(HostileOutputs, PipesAreRefusedNotWaitedOn) {
  const std::string dir = test::temp_dir("fifo");
  const std::string fifo = dir + "/pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // `timeout` turns a blocked command into a failure instead of a hung test.
  const std::string bag_fifo = dir + "/pipe.bag";
  ASSERT_EQ(::mkfifo(bag_fifo.c_str(), 0600), 0);
  const auto refused = [&](const std::string& args, const std::string& what,
                           const std::string& name = "pipe") {
    std::string out;
    EXPECT_EQ(test::run("timeout 60 " + test::cli() + " " + args, &out), 2) << args << "\n" << out;
    EXPECT_NE(out.find(name + ": " + what + " is a pipe (FIFO), not a regular file"),
              std::string::npos)
        << args << "\n"
        << out;
  };
  refused("evaluate --data " + fifo + " --model " + fitted_model(), "flight file");
  refused("evaluate --data " + files().flight + " --model " + fifo, "model file");
  refused("calibrate --data " + files().flight + " --model " + fifo + " --out " + dir + "/o.yaml",
          "model file");
  refused("diagnose --data " + fifo + " --model " + fitted_model(), "flight file");
  refused("info --data " + fifo, "flight file");
  refused("simulate --scenario " + fifo + " --out " + dir + "/o.h5", "scenario file");
  refused("navigate --data " + files().flight + " --map " + fifo + " --anomaly mag_1_c",
          "map file");
  refused("convert " + bag_fifo + " " + dir + "/o.h5", "bag", "pipe.bag");
}

TEST(HostileOutputs, RandomEffectsBeyondWhatCanBeDrawnAreRefused) {
  const std::string scenario = test::source_dir() + "/config/scenarios/rostest_short.yaml";
  expect_refusal("simulate --scenario " + scenario + " --out " + files().dir +
                     "/r.h5 --random-effects 1 --random-count 135",
                 {"--random-count 135", "exceeds the 130 distinct effects"});
  EXPECT_FALSE(exists(files().dir + "/r.h5"));
}

TEST(HostileOutputs, AnUnknownTransformListsEveryKnownOne) {
  expect_refusal(
      "calibrate --data " + files().flight + " --model " + files().model +
          " --term 'field:cur_strb|nope(2)' --out " + files().dir + "/t.yaml",
      {"unknown transform 'nope'", "play(r)", "sat(s)", "step(x0)", "ramp(x0)", "decay(tau_s)"});
}

TEST(HostileOutputs, LoopOnlyFlagsWithoutTheLoopAreRefused) {
  // --choose-lambda, --validate, --no-exchange, --no-chance-control, --no-look-ahead,
  // --no-refine, --keep-factors, --no-steady-factors, --norm-alone, --slow-lines-last and
  // --slow-names-kept change the loop
  // (--apply); without it they would be ignored.
  expect_refusal(
      "diagnose --data " + files().flight + " --model " + files().model + " --choose-lambda",
      {"--choose-lambda: only with --apply"});
  expect_refusal("diagnose --data " + files().flight + " --model " + files().model +
                     " --validate " + files().flight,
                 {"--validate: only with --apply"});
  expect_refusal(
      "diagnose --data " + files().flight + " --model " + files().model + " --no-exchange",
      {"--no-exchange: only with --apply"});
  for (const std::string flag :
       {"--no-chance-control", "--no-look-ahead", "--no-refine", "--keep-factors",
        "--no-steady-factors", "--norm-alone", "--slow-lines-last", "--slow-names-kept"})
    expect_refusal("diagnose --data " + files().flight + " --model " + files().model + " " + flag,
                   {flag + ": only with --apply"});
}

}  // namespace
}  // namespace magcomp
