// magcomp calibrate: fit a model's coefficients on calibration segments of one or more flights.
#include <cmath>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "common.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/output_guard.h"
#include "magcomp/core/model/model.h"
#include "subcommands.h"

namespace magcomp::cli {

void add_calibrate(CLI::App& app) {
  auto* cmd = app.add_subcommand("calibrate", "fit the model (TL + terms) on calibration segments");
  auto data = std::make_shared<std::string>();
  auto model_path = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>();
  auto terms = std::make_shared<std::vector<std::string>>();
  auto slow_terms = std::make_shared<std::vector<std::string>>();
  auto holdout_truth = std::make_shared<std::string>("mag_1_c");
  auto truth = std::make_shared<std::string>();
  auto track = std::make_shared<std::string>("truth");
  cmd->add_option("--data", *data, "flight HDF5 file(s), comma-separated")->required();
  cmd->add_option("--model", *model_path, "model YAML (plain or fitted: refit)")->required();
  cmd->add_option("--term", *terms, "add a term, e.g. current:cur_strb (repeatable)");
  cmd->add_option("--slow-term", *slow_terms,
                  "add a term too slow for the band-pass (a heater, a drift), fitted after it "
                  "against fit.reference (default mag_1_c) on the calibration segments, "
                  "unfiltered (repeatable; diagnose prints it for such a candidate)");
  cmd->add_option("--out", *out, "fitted model YAML to write")->required();
  cmd->add_option("--holdout-truth", *holdout_truth,
                  "reference field for the model's error on the lines it is not fitted on (its "
                  "variance enters each sample's uncertainty); empty: none (default mag_1_c, "
                  "where the flights have it)");
  cmd->add_option("--truth", *truth,
                  "the reference of this fit: for a reference fit (fit.method reference) and the "
                  "slow stage (fit.reference), and for the held-out error (--holdout-truth): a "
                  "field, or map:M.h5 (the anomaly map along --track plus the IGRF and the "
                  "diurnal: calibrate with no stinger)");
  cmd->add_option("--track", *track, "with --truth map:M.h5: truth (lat/lon), ins or filter")
      ->check(CLI::IsMember({"truth", "ins", "filter"}));
  cmd->callback([=] {
    const std::vector<std::string> inputs = flight_paths("--data", *data);
    std::vector<OutputGuard::File> others = {{"--model", *model_path}};
    for (const auto& m : map_inputs("--truth", {*truth})) others.push_back(m);
    OutputGuard guard = guard_for(inputs, others);
    guard.add_output("--out", *out);  // before the work: never over a file it reads
    Model model = load_model_yaml(*model_path);
    if (!truth->empty()) model.fit.reference = *truth;
    const std::string holdout = truth->empty() ? *holdout_truth : *truth;
    for (const std::string& t : *terms) {
      try {
        model.add_term(t);
      } catch (const Error& e) {
        throw Error(std::string("--term: ") + e.what());
      }
    }
    for (const std::string& t : *slow_terms) {
      try {
        model.add_slow_term(t, truth->empty() ? "mag_1_c" : *truth);
      } catch (const Error& e) {
        throw Error(std::string("--slow-term: ") + e.what());
      }
    }
    auto flights = read_flights(inputs);
    for (FlightData& f : flights)
      add_map_references(&f, {model.fit.reference, holdout}, *track, &model);
    std::vector<const FlightData*> ptrs;
    for (const auto& f : flights) ptrs.push_back(&f);
    fit_model(model, ptrs);
    std::string holdout_note;
    if (!holdout.empty() && !model.neural) {
      const auto [var, rows] = holdout_error_variance_nT2(model, ptrs, holdout);
      model.report.holdout_error_variance_nT2 = var;
      std::ostringstream note;
      note << std::setprecision(4);
      if (rows > 0 && std::isfinite(var))
        note << "held-out error std " << std::sqrt(var) << " nT against " << holdout << " on "
             << rows << " samples of lines not fitted (in each sample's variance)\n";
      holdout_note = note.str();
    }
    if (!std::isfinite(model.report.holdout_error_variance_nT2))
      model.report.holdout_error_variance_nT2 = NAN;  // not written
    guard.check_inputs_unchanged();
    save_model_yaml(model, *out, guard.input_paths());
    const FitReport& r = model.report;
    std::cout << "calibrated " << model.scalar << " with " << model.vector << ": "
              << model.coefficients.size() << " coefficients, " << r.samples << " samples in "
              << r.segments << " segment(s)\n"
              << std::setprecision(4) << "condition number ";
    if (std::isfinite(r.condition_number)) {
      std::cout << r.condition_number;
    } else {
      std::cout << "infinite (singular columns)";
    }
    std::cout << ", fit residual std " << r.residual_std_nT << " nT\n";
    std::cout << holdout_note;
    for (const auto& e : r.estimates) std::cout << "estimated: " << e << "\n";
    for (const auto& w : r.warnings) std::cout << "warning: " << w << "\n";
    std::cout << "wrote " << *out << "\n";
  });
}

}  // namespace magcomp::cli
