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

namespace {

// What `magcomp calibrate` is asked, as given on the command line.
struct CalibrateArgs {
  std::string data, model_path, out, holdout_truth = "mag_1_c", truth, track = "truth";
  std::vector<std::string> terms, slow_terms;
};

// The model to fit: the file's, its reference set by --truth, the --term and --slow-term added
// (an error names the option).
Model model_to_fit(const CalibrateArgs& a) {
  Model model = load_model_yaml(a.model_path);
  if (!a.truth.empty()) model.fit.reference = a.truth;
  for (const std::string& t : a.terms) {
    try {
      model.add_term(t);
    } catch (const Error& e) {
      throw Error(std::string("--term: ") + e.what());
    }
  }
  for (const std::string& t : a.slow_terms) {
    try {
      model.add_slow_term(t, a.truth.empty() ? "mag_1_c" : a.truth);
    } catch (const Error& e) {
      throw Error(std::string("--slow-term: ") + e.what());
    }
  }
  return model;
}

// The model's error on the lines it is not fitted on against `holdout` (nT^2), kept in the
// model's report; returns the line that says so ("" when there is none).
std::string measure_holdout(Model* model, const std::vector<const FlightData*>& flights,
                            const std::string& holdout) {
  if (holdout.empty() || model->neural) return "";
  const auto [var, rows] = holdout_error_variance_nT2(*model, flights, holdout);
  model->report.holdout_error_variance_nT2 = var;
  std::ostringstream note;
  note << std::setprecision(4);
  if (rows > 0 && std::isfinite(var))
    note << "held-out error std " << std::sqrt(var) << " nT against " << holdout << " on " << rows
         << " samples of lines not fitted (in each sample's variance)\n";
  return note.str();
}

// What the fit did, for the terminal.
void print_calibration(const Model& model, const std::string& holdout_note,
                       const std::string& out) {
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
  std::cout << "wrote " << out << "\n";
}

void run_calibrate(const CalibrateArgs& a) {
  const std::vector<std::string> inputs = flight_paths("--data", a.data);
  std::vector<OutputGuard::File> others = {{"--model", a.model_path}};
  for (const auto& m : map_inputs("--truth", {a.truth})) others.push_back(m);
  OutputGuard guard = guard_for(inputs, others);
  guard.add_output("--out", a.out);  // before the work: never over a file it reads
  Model model = model_to_fit(a);
  const std::string holdout = a.truth.empty() ? a.holdout_truth : a.truth;
  auto flights = read_flights(inputs);
  for (FlightData& f : flights)
    add_map_references(&f, {model.fit.reference, holdout}, a.track, &model);
  std::vector<const FlightData*> ptrs;
  std::vector<std::pair<std::string, const FlightData*>> named;
  for (const auto& f : flights) {
    ptrs.push_back(&f);
    named.emplace_back("--data", &f);
  }
  require_distinct_flights(named, model.scalar);
  fit_model(model, ptrs);
  const std::string holdout_note = measure_holdout(&model, ptrs, holdout);
  if (!std::isfinite(model.report.holdout_error_variance_nT2))
    model.report.holdout_error_variance_nT2 = NAN;  // not written
  guard.check_inputs_unchanged();
  save_model_yaml(model, a.out, guard.input_paths());
  print_calibration(model, holdout_note, a.out);
}

}  // namespace

void add_calibrate(CLI::App& app) {
  auto* cmd = app.add_subcommand("calibrate", "fit the model (TL + terms) on calibration segments");
  auto a = std::make_shared<CalibrateArgs>();
  cmd->add_option("--data", a->data, "flight HDF5 file(s), comma-separated")->required();
  cmd->add_option("--model", a->model_path, "model YAML (plain or fitted: refit)")->required();
  cmd->add_option("--term", a->terms, "add a term, e.g. current:cur_strb (repeatable)");
  cmd->add_option("--slow-term", a->slow_terms,
                  "add a term too slow for the calibration segments to size (a heater, a "
                  "drift), fitted after the other columns against fit.reference (default "
                  "mag_1_c) on the calibration segments and fit.slow_lines, unfiltered "
                  "(repeatable; diagnose prints it for such a candidate)");
  cmd->add_option("--out", a->out, "fitted model YAML to write")->required();
  cmd->add_option("--holdout-truth", a->holdout_truth,
                  "reference field for the model's error on the lines it is not fitted on (its "
                  "variance enters each sample's uncertainty); empty: none (default mag_1_c, "
                  "where the flights have it)");
  cmd->add_option("--truth", a->truth,
                  "the reference of this fit: for a reference fit (fit.method reference) and the "
                  "slow stage (fit.reference), and for the held-out error (--holdout-truth): a "
                  "field, or map:M.h5 (the anomaly map along --track plus the IGRF and the "
                  "diurnal: calibrate with no stinger)");
  cmd->add_option("--track", a->track, "with --truth map:M.h5: truth (lat/lon), ins or filter")
      ->check(CLI::IsMember({"truth", "ins", "filter"}));
  cmd->callback([a] { run_calibrate(*a); });
}

}  // namespace magcomp::cli
