// magcomp evaluate: a fitted model's error against a reference, per line, per flight condition,
// per heading sector; --report writes an HTML page with plots.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "attribution_output.h"
#include "common.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/evaluate/flight_conditions.h"
#include "magcomp/core/evaluate/network_gain.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/output_guard.h"
#include "magcomp/core/neural/attribution.h"
#include "subcommands.h"

namespace magcomp::cli {
namespace {

nlohmann::json to_json(const Evaluation& ev) {
  nlohmann::json j;
  j["n"] = ev.n;
  j["nan_samples"] = ev.nan_samples;
  j["rmse_nT"] = ev.rmse_nT;
  j["std_nT"] = ev.std_nT;
  const auto num = json_figure;
  j["uncompensated_std_nT"] = num(ev.uncompensated_std_nT);
  j["improvement_ratio"] = num(ev.improvement_ratio);
  j["coverage_1sigma"] = num(ev.coverage_1sigma);
  j["coverage_2sigma"] = num(ev.coverage_2sigma);
  j["per_line"] = nlohmann::json::array();
  for (const auto& l : ev.per_line) {
    j["per_line"].push_back({{"line", l.line},
                             {"n", l.n},
                             {"rmse_nT", l.rmse_nT},
                             {"std_nT", num(l.std_nT)},
                             {"uncompensated_std_nT", num(l.uncompensated_std_nT)},
                             {"improvement_ratio", num(l.improvement_ratio)}});
  }
  nlohmann::json fom;
  fom["fom_nT"] = num(ev.fom.fom_nT);
  fom["uncompensated_fom_nT"] = num(ev.fom.uncompensated_fom_nT);
  fom["maneuvers"] = ev.fom.signatures.size();
  fom["where"] = ev.fom.where;
  fom["signatures"] = nlohmann::json::array();
  for (const auto& s : ev.fom.signatures) {
    fom["signatures"].push_back(
        {{"axis", s.axis},
         {"heading", s.heading},
         {"start_tt_s", s.start_tt_s},
         {"end_tt_s", s.end_tt_s},
         {"peak_to_peak_nT", s.peak_to_peak_nT},
         {"uncompensated_peak_to_peak_nT", s.uncompensated_peak_to_peak_nT}});
  }
  j["fom"] = fom;
  for (const auto& [key, groups] :
       {std::pair{"per_condition", &ev.per_condition}, std::pair{"per_heading", &ev.per_heading}}) {
    j[key] = nlohmann::json::array();
    for (const auto& g : *groups)
      j[key].push_back({{"name", g.name}, {"n", g.n}, {"std_nT", g.std_nT}});
  }
  return j;
}

void print_groups(const char* title, const std::vector<GroupStats>& groups) {
  std::printf("\n%-16s %8s %10s\n", title, "n", "std_nT");
  for (const auto& g : groups) {
    std::printf("%-16s %8ld %10.3f\n", g.name.c_str(), static_cast<long>(g.n), g.std_nT);
  }
}

// The per-sample series the report plots, as an HDF5 file in the flight schema.
void write_series(const std::string& path, const FlightData& flight, const Model& model,
                  const Evaluation& ev, const std::string& truth, const Evaluation* baseline,
                  const std::vector<std::string>& inputs) {
  FlightData s;
  s.set_source(path);
  for (const char* f :
       {"tt", "line", "lat", "lon", "utm_x", "utm_y", "ins_yaw", "ins_roll", "ins_pitch"}) {
    if (flight.has(f)) s.set(f, flight.column(f));
  }
  const Eigen::VectorXd measured = aligned_scalar(model, flight);
  s.set("measured", measured);
  s.set("compensated", ev.compensated_nT);
  s.set("correction", measured - ev.compensated_nT);
  s.set("truth", flight.column(truth));
  s.set("error", ev.error_nT);
  if (ev.variance_nT2.size() == ev.error_nT.size()) s.set("variance", ev.variance_nT2);
  if (baseline) s.set("error_baseline", baseline->error_nT);
  const auto cond = classify_conditions(flight);
  const auto sector = heading_sectors(flight);
  Eigen::VectorXd c(flight.size()), h(flight.size());
  for (Eigen::Index i = 0; i < flight.size(); ++i) {
    c[i] = static_cast<double>(cond[static_cast<size_t>(i)]);
    h[i] = sector[static_cast<size_t>(i)];
  }
  s.set("condition", c);
  s.set("heading_sector", h);
  for (const auto& name : flight.names()) {
    if (name.rfind("cur_", 0) == 0 || name.rfind("vol_", 0) == 0) s.set(name, flight.column(name));
  }
  write_flight_h5(s, path, inputs);
}

// The per-line table, the groups, the FOM, the coverage and the total line of one evaluation.
void print_evaluation(const Evaluation& ev, const Evaluation* base) {
  std::printf("%-10s %8s %12s %10s %16s %9s%s\n", "line", "n", "rmse_nT", "std_nT", "uncomp_std_nT",
              "IR", base ? "   baseline_std_nT" : "");
  for (size_t k = 0; k < ev.per_line.size(); ++k) {
    const auto& l = ev.per_line[k];
    std::printf("%-10.2f %8ld %12.3f %10s %16s %9s", l.line, static_cast<long>(l.n), l.rmse_nT,
                figure(l.std_nT, "%.3f").c_str(), figure(l.uncompensated_std_nT, "%.3f").c_str(),
                figure(l.improvement_ratio, "%.1f").c_str());
    if (base && k < base->per_line.size())
      std::printf(" %17s", figure(base->per_line[k].std_nT, "%.3f").c_str());
    std::printf("\n");
  }
  print_groups("condition", ev.per_condition);
  print_groups("heading", ev.per_heading);
  if (ev.nan_samples > 0) {
    std::printf("\n(%ld samples with NaN in the model inputs or the reference were skipped)\n",
                static_cast<long>(ev.nan_samples));
  }
  if (!ev.fom.signatures.empty()) {
    std::printf("\nfigure of merit on %s: %zu maneuvers\n", ev.fom.where.c_str(),
                ev.fom.signatures.size());
    std::printf("  %-6s %-7s %12s %12s %14s\n", "axis", "heading", "start_tt_s", "p-p_nT",
                "uncomp_p-p_nT");
    for (const auto& s : ev.fom.signatures) {
      std::printf("  %-6s %-7s %12.1f %12.3f %14.3f\n", s.axis.c_str(), s.heading.c_str(),
                  s.start_tt_s, s.peak_to_peak_nT, s.uncompensated_peak_to_peak_nT);
    }
    std::printf("  FOM %s nT (uncompensated %s nT)\n", figure(ev.fom.fom_nT, "%.3f").c_str(),
                figure(ev.fom.uncompensated_fom_nT, "%.3f").c_str());
  }
  if (std::isfinite(ev.coverage_1sigma)) {
    std::printf("\nuncertainty: %.1f%% of the errors within 1 sigma, %.1f%% within 2 sigma\n",
                100 * ev.coverage_1sigma, 100 * ev.coverage_2sigma);
  }
  std::printf("\n%-10s %8ld %12.3f %10.3f %16s %9s", "all", static_cast<long>(ev.n), ev.rmse_nT,
              ev.std_nT, figure(ev.uncompensated_std_nT, "%.3f").c_str(),
              figure(ev.improvement_ratio, "%.1f").c_str());
  if (base) std::printf(" %17.3f", base->std_nT);
  std::printf("\n");
}

// With a trained network: whether its gain carries over to this flight (printed, and in the JSON
// as `network_gain`); nothing for a model without one.
void add_network_gain(const Model& model, const FlightData& flight, const std::string& truth,
                      const Evaluation& ev, nlohmann::json* j) {
  if (!model.neural || !model.neural->trained()) return;
  const NetworkGain g = network_gain(model, flight, truth, ev);
  std::printf("%s\n", g.verdict.c_str());
  (*j)["network_gain"] = {{"physics_rmse_nT", json_figure(g.physics.rmse_nT)},
                          {"physics_std_nT", json_figure(g.physics.std_nT)},
                          {"gain_std", json_figure(g.gain_std)},
                          {"carries_over", g.carries_over},
                          {"output_gain", model.neural->output_gain},
                          {"worse", g.worse},
                          {"verdict", g.verdict}};
}

// The attribution on a flight: the model's network's, or with an ensemble (--ensemble) the
// mean of every network's (average_attributions).
Attribution explain(const Model& model, const std::vector<Model>& ensemble,
                    const FlightData& flight) {
  std::vector<Attribution> each = {permutation_importance(model, flight)};
  for (const Model& m : ensemble) each.push_back(permutation_importance(m, flight));
  return average_attributions(each);
}

// One flight: the table, the JSON and the report.
void evaluate_one(const std::string& data, const Model& model, const Model* baseline_model,
                  const std::string& model_path, const std::string& baseline_path,
                  const std::string& truth, const std::string& json_path, const std::string& report,
                  const OutputGuard& guard, const std::string& track, bool with_explain,
                  const std::vector<Model>& ensemble) {
  const std::vector<std::string> inputs = guard.input_paths();
  FlightData flight = read_flight(data);
  add_map_references(&flight, {truth}, track, &model);
  // The per-sample variance is kept only for the report's series (the table shows its coverage).
  const bool series = !report.empty();
  const Evaluation ev = evaluate_model(model, flight, truth, series);
  std::unique_ptr<Evaluation> base;
  if (baseline_model)
    base = std::make_unique<Evaluation>(evaluate_model(*baseline_model, flight, truth, series));
  std::unique_ptr<Attribution> attribution;
  if (with_explain) attribution = std::make_unique<Attribution>(explain(model, ensemble, flight));
  guard.check_inputs_unchanged();
  print_evaluation(ev, base.get());
  nlohmann::json j = to_json(ev);
  add_network_gain(model, flight, truth, ev, &j);
  if (attribution) {
    print_attribution(*attribution);
    j["attribution"] = attribution_json(*attribution);
  }
  j["data"] = data;
  j["model"] = model_path;
  j["truth"] = truth;
  j["terms"] = model.terms;
  if (base) {
    j["baseline"] = to_json(*base);
    j["baseline"]["model"] = baseline_path;
  }
  if (!json_path.empty()) write_file_atomic(json_path, j.dump(2) + "\n", inputs);
  if (report.empty()) return;
  make_report_dir(report);
  write_series(report + "/series.h5", flight, model, ev, truth, base.get(), inputs);
  write_file_atomic(report + "/evaluation.json", j.dump(2) + "\n", inputs);
  run_report_page("magcomp_report.py", report, "series.h5 and evaluation.json");
}

// What `magcomp evaluate` is asked, as given on the command line.
struct EvaluateArgs {
  std::string data, model_path, truth = "mag_1_c", json_path, report, baseline_path;
  std::string track = "truth";
  std::string ensemble;  // other trainings of the network, comma-separated (--ensemble)
  bool explain = false;
};

// Several flights: each evaluated in turn (memory is one flight's columns), then pooled.
void evaluate_several(const EvaluateArgs& a, const std::vector<std::string>& paths,
                      const Model& model, const Model* baseline_model, const OutputGuard& guard,
                      const std::vector<Model>& ensemble) {
  nlohmann::json j;
  j["flights"] = nlohmann::json::array();
  double n = 0, sum_sq = 0, sum_var = 0, sum_unc = 0, n_unc = 0;
  for (const std::string& path : paths) {
    std::printf("flight %s\n", path.c_str());
    FlightData flight = read_flight(path);
    add_map_references(&flight, {a.truth}, a.track, &model);
    const Evaluation ev = evaluate_model(model, flight, a.truth, false);
    std::unique_ptr<Evaluation> base;
    if (baseline_model)
      base = std::make_unique<Evaluation>(evaluate_model(*baseline_model, flight, a.truth, false));
    print_evaluation(ev, base.get());
    nlohmann::json f = to_json(ev);
    add_network_gain(model, flight, a.truth, ev, &f);
    if (a.explain) {
      const Attribution at = explain(model, ensemble, flight);
      print_attribution(at);
      f["attribution"] = attribution_json(at);
    }
    std::printf("\n");
    f["data"] = path;
    if (base) f["baseline"] = to_json(*base);
    j["flights"].push_back(f);
    const double k = static_cast<double>(ev.n);
    n += k;
    sum_sq += ev.rmse_nT * ev.rmse_nT * k;
    sum_var += ev.std_nT * ev.std_nT * k;
    if (std::isfinite(ev.uncompensated_std_nT)) {
      sum_unc += ev.uncompensated_std_nT * ev.uncompensated_std_nT * k;
      n_unc += k;
    }
  }
  const double rmse = std::sqrt(sum_sq / n), std_nT = std::sqrt(sum_var / n);
  const double unc = n_unc > 0 ? std::sqrt(sum_unc / n_unc) : NAN;
  guard.check_inputs_unchanged();
  std::printf("%-10s %8ld %12.3f %10.3f %16s %9s   (%zu flights)\n", "all", static_cast<long>(n),
              rmse, std_nT, figure(unc, "%.3f").c_str(),
              figure(std_nT > 0 ? unc / std_nT : NAN, "%.1f").c_str(), paths.size());
  j["n"] = static_cast<long>(n);
  j["rmse_nT"] = rmse;
  j["std_nT"] = std_nT;
  j["uncompensated_std_nT"] = json_figure(unc);
  j["improvement_ratio"] = json_figure(std_nT > 0 ? unc / std_nT : NAN);
  j["data"] = paths;
  j["model"] = a.model_path;
  j["truth"] = a.truth;
  j["terms"] = model.terms;
  if (!a.json_path.empty()) write_file_atomic(a.json_path, j.dump(2) + "\n", guard.input_paths());
}

void run_evaluate(const EvaluateArgs& a) {
  const std::vector<std::string> paths = flight_paths("--data", a.data);
  std::vector<OutputGuard::File> others = {{"--model", a.model_path},
                                           {"--baseline", a.baseline_path}};
  const std::vector<std::string> ensemble_paths =
      a.ensemble.empty() ? std::vector<std::string>{} : flight_paths("--ensemble", a.ensemble);
  for (const std::string& p : ensemble_paths) others.push_back({"--ensemble", p});
  for (const auto& m : map_inputs("--truth", {a.truth})) others.push_back(m);
  OutputGuard guard = guard_for(paths, others);
  guard.add_output("--json", a.json_path);
  guard.add_output_dir("--report", a.report,
                       {"series.h5", "evaluation.json", "index.html", "timeseries.png",
                        "groups.png", "map.png", "spectrum.png", "channels.png"});
  if (paths.size() > 1 && !a.report.empty())
    throw Error("--report takes one flight (--data holds " + std::to_string(paths.size()) + ")");
  const Model model = load_model_yaml(a.model_path);
  if (!model.fitted()) throw Error(a.model_path + ": model has no coefficients; run calibrate");
  if (a.explain && !(model.neural && model.neural->trained()))
    throw Error("--explain: " + a.model_path +
                " has no trained neural stage (the attribution explains a network)");
  if (!ensemble_paths.empty() && !a.explain)
    throw Error("--ensemble: only with --explain (the networks' attributions are averaged)");
  // Other trainings of the same network (magcomp train --seed): the same inputs, in order.
  std::vector<Model> ensemble;
  for (const std::string& p : ensemble_paths) {
    Model m = load_model_yaml(p);
    if (!(m.neural && m.neural->trained()))
      throw Error("--ensemble: " + p + " has no trained neural stage");
    if (m.neural->features != model.neural->features)
      throw Error("--ensemble: " + p + ": its network reads other inputs than " + a.model_path +
                  "'s (neural.features must be the same, in the same order)");
    ensemble.push_back(std::move(m));
  }
  std::unique_ptr<Model> baseline_model;
  if (!a.baseline_path.empty()) {
    baseline_model = std::make_unique<Model>(load_model_yaml(a.baseline_path));
    if (!baseline_model->fitted())
      throw Error(a.baseline_path + ": model has no coefficients; run calibrate");
  }
  if (paths.size() == 1)
    evaluate_one(paths[0], model, baseline_model.get(), a.model_path, a.baseline_path, a.truth,
                 a.json_path, a.report, guard, a.track, a.explain, ensemble);
  else
    evaluate_several(a, paths, model, baseline_model.get(), guard, ensemble);
}

}  // namespace

void add_evaluate(CLI::App& app) {
  auto* cmd = app.add_subcommand("evaluate", "compare a fitted model with a reference field");
  auto a = std::make_shared<EvaluateArgs>();
  cmd->add_option("--data", a->data, "flight HDF5 file(s), comma-separated")->required();
  cmd->add_option("--model", a->model_path, "fitted model YAML")->required();
  cmd->add_option("--truth", a->truth,
                  "reference field (default mag_1_c), or map:M.h5: the anomaly map along --track "
                  "plus the IGRF and the diurnal (no stinger needed)");
  cmd->add_option("--track", a->track,
                  "with --truth map:M.h5, where the map is read: truth (lat/lon), ins, or filter "
                  "(the navigation filter on the model's anomaly); default truth")
      ->check(CLI::IsMember({"truth", "ins", "filter"}));
  cmd->add_option("--json", a->json_path, "write the evaluation JSON here");
  cmd->add_option("--report", a->report, "write an HTML report with plots into this directory");
  cmd->add_option("--baseline", a->baseline_path,
                  "a second fitted model to compare with (before/after)");
  cmd->add_flag("--explain", a->explain,
                "with a trained neural stage: each input's share of the network's prediction on "
                "each flight (permutation importance: the rise of its squared error against its "
                "target when the input is shuffled), in the table and the JSON (attribution)");
  cmd->add_option("--ensemble", a->ensemble,
                  "with --explain: other trainings of the same network (magcomp train --seed S, "
                  "the same neural.features), comma-separated; the attribution is the mean of "
                  "every network's, --model's included (what one training leans on moves with "
                  "its seed)");
  cmd->callback([a] { run_evaluate(*a); });
}

}  // namespace magcomp::cli
