// magcomp diagnose: rank the physical effects the model misses, and say which --term to add;
// with --apply, run the whole loop (diagnose, add, refit) and write the final model.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "common.h"
#include "diagnose_json.h"
#include "diagnose_rounds_table.h"
#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/diagnose_loop.h"
#include "magcomp/core/diagnose/diagnose_season.h"
#include "magcomp/core/diagnose/term_support.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/output_guard.h"
#include "magcomp/core/nav/map_reference.h"
#include "network_attribution.h"
#include "subcommands.h"

namespace magcomp::cli {
namespace {

void print_diagnosis(const Model& model, const Diagnosis& dx, int top, const std::string& data,
                     const std::string& model_path) {
  std::printf("model: %s with %s, terms:", model.scalar.c_str(), model.vector.c_str());
  for (const auto& t : model.terms) std::printf(" %s", t.text().c_str());
  std::printf("\nsplit: %s\n", dx.split.c_str());
  std::printf("  selection lines:");
  for (double l : dx.selection_lines) std::printf(" %g", l);
  std::printf("\n  confirmation lines:");
  for (double l : dx.confirmation_lines) std::printf(" %g", l);
  std::printf(
      "\nbaseline: held-out error std %.3f nT (selection %.3f, confirmation %.3f; line means "
      "removed) on %ld samples; fit on %ld; %ld terms fitted in the search\n\n",
      dx.baseline_std_nT, dx.baseline_selection_std_nT, dx.baseline_confirmation_std_nT,
      static_cast<long>(dx.heldout_samples), static_cast<long>(dx.fit_samples),
      dx.candidates_tried);
  std::printf("%-4s %-34s %9s %9s %9s %8s  %-40s %s\n", "rank", "term (--term)", "std_after",
              "explained", "selection", "confirm", "estimate", "effect");
  for (size_t k = 0; k < dx.candidates.size() && static_cast<int>(k) < top; ++k) {
    const Candidate& c = dx.candidates[k];
    std::printf(
        "%-4zu %-34s %9.3f %8.1f%% %8.1f%% %7.1f%%  %-40s %s%s\n", k + 1, c.term.text().c_str(),
        c.std_after_nT, 100 * c.explained_fraction, 100 * c.explained_selection,
        100 * c.explained_confirmation, c.estimate.c_str(), c.effect.c_str(),
        c.accepted ? (c.chosen_on_confirmation ? "  [chosen on the confirmation lines]" : "")
                   : "  [rejected: not confirmed]");
  }
  const ExplainableShare& x = dx.explainable;
  if (x.computed) {
    std::printf(
        "\nwhat remains: a flexible model of all channels predicts %.1f%% ± %.1f%% of the "
        "held-out residual (noise floor %.1f%%)\n",
        100 * x.share, 100 * x.uncertainty, 100 * x.noise_floor);
    std::printf("  channels (alone):");
    for (size_t k = 0; k < x.channels.size() && k < 5; ++k)
      std::printf(" %s %.1f%%", x.channels[k].first.c_str(), 100 * x.channels[k].second);
    if (!x.time_scales.empty()) {
      std::printf("\n  time scales of the predictable part:");
      for (const auto& [band, v] : x.time_scales) std::printf(" %s %.0f%%", band.c_str(), 100 * v);
    }
    if (!x.lines.empty()) {
      std::printf("\n  where:");
      for (size_t k = 0; k < x.lines.size() && k < 4; ++k)
        std::printf(" line %g %.0f%%", x.lines[k].first, 100 * x.lines[k].second);
    }
    std::printf("\n");
  }
  const JointSet& js = dx.joint;
  if (!js.terms.empty()) {
    std::printf(
        "\nchosen together (%zu terms of a pool of %d, the same set in %.0f%% of %d "
        "resamplings of the held-out lines):\n  ",
        js.terms.size(), js.pool_size, 100 * js.stability, kJointResamples);
    for (size_t k = 0; k < js.terms.size(); ++k)
      std::printf("%s%s", k ? " + " : "", js.terms[k].text().c_str());
    std::printf("\n  held-out %.3f nT (selection %.3f, confirmation %.3f); each alone:",
                js.heldout_std_nT, js.selection_std_nT, js.confirmation_std_nT);
    for (double v : js.alone_std_nT) std::printf(" %.3f", v);
    if (!js.best_single.empty())
      std::printf(" nT; the best single term, %s: %.3f nT", js.best_single.c_str(),
                  js.best_single_std_nT);
    std::printf("\n");
  }
  print_network_checks(dx.network, "");
  std::printf("\nverdict: %s\n", dx.verdict.c_str());
  if (!dx.candidates.empty() && dx.candidates.front().accepted &&
      dx.candidates.front().explained_fraction >= 0.05) {
    std::printf("to add it:\n  magcomp calibrate --data %s --model %s --%s '%s' --out NEW.yaml\n",
                data.c_str(), model_path.c_str(), dx.candidates.front().slow ? "slow-term" : "term",
                dx.candidates.front().term.text().c_str());
  }
  std::printf("\nresidual vs channel (held-out, line means removed), strongest first:\n");
  std::printf("  %-14s %8s %9s %8s\n", "channel", "pearson", "spearman", "MI_bits");
  for (size_t k = 0; k < dx.associations.size() && k < 8; ++k) {
    const auto& a = dx.associations[k];
    std::printf("  %-14s %8.3f %9.3f %8.3f\n", a.channel.c_str(), a.pearson, a.spearman,
                a.mutual_information_bits);
  }
  for (const auto& note : dx.notes) std::printf("note: %s\n", note.c_str());
}

// With the map as the reference, what the floor and the verdict mean.
void print_map_note(const std::string& truth) {
  std::string path;
  if (!nav::names_map(truth, &path)) return;
  std::printf(
      "note: the reference is the map %s: its own error and its interpolation are part of every "
      "held-out error and of the floor; \"complete\" means complete to the sensor noise and the "
      "map's error together\n",
      path.c_str());
}

// Several flights: each diagnosed in turn (read, diagnosed, released: one flight in memory at a
// time), then the candidates ranked across them.
void diagnose_several(const Model& model_in, const std::vector<std::string>& paths,
                      const std::string& model_path, const std::string& truth,
                      const std::string& json_path, int top, const DiagnoseOptions& options,
                      const OutputGuard& guard,
                      const std::function<FlightData(const std::string&)>& read) {
  Model model = model_in;
  {  // one flight named twice would be ranked twice (columns are read on first use: tt, scalar;
     // the reader's notes are printed where each flight is read for its diagnosis)
    std::vector<FlightData> flights;
    for (const auto& p : paths) flights.push_back(read_flight_h5(p));
    std::vector<std::pair<std::string, const FlightData*>> named;
    for (const auto& f : flights) named.emplace_back("--data", &f);
    require_distinct_flights(named, model.scalar);
  }
  if (!model.fitted()) {  // fitted on every flight's calibration segments
    std::vector<FlightData> flights;
    for (const auto& p : paths) flights.push_back(read(p));
    std::vector<const FlightData*> all;
    for (const auto& f : flights) all.push_back(&f);
    fit_model(model, all);
  }
  std::vector<Diagnosis> per_flight;
  nlohmann::json j;
  j["data"] = paths;
  j["model"] = model_path;
  j["truth"] = truth;
  j["flights"] = nlohmann::json::array();
  for (const std::string& path : paths) {
    const FlightData flight = read(path);
    per_flight.push_back(diagnose(model, flight, truth, options));
    const Diagnosis& dx = per_flight.back();
    std::printf("flight %s: held-out std %.3f nT; top:", path.c_str(), dx.baseline_std_nT);
    for (size_t k = 0; k < dx.candidates.size() && k < 3; ++k) {
      const Candidate& c = dx.candidates[k];
      std::printf(" %s %.1f%%%s", c.term.text().c_str(), 100 * c.explained_fraction,
                  c.accepted ? "" : " [rejected]");
    }
    std::printf("\n  verdict: %s\n", dx.verdict.c_str());
    std::fflush(stdout);
    nlohmann::json f = to_json(dx);
    f["data"] = path;
    j["flights"].push_back(f);
  }
  const SeasonDiagnosis season = merge_diagnoses(per_flight);
  guard.check_inputs_unchanged();
  std::printf("\n%-4s %-34s %9s %14s  %s\n", "rank", "term (--term)", "accepted", "mean_explained",
              "per flight");
  nlohmann::json candidates = nlohmann::json::array();
  for (size_t k = 0; k < season.candidates.size(); ++k) {
    const SeasonCandidate& c = season.candidates[k];
    nlohmann::json per = nlohmann::json::array();
    for (double e : c.explained) per.push_back(json_figure(e));
    candidates.push_back({{"term", c.term.text()},
                          {"shape", c.shape},
                          {"accepted_on", c.accepted_on},
                          {"scored_on", c.scored_on},
                          {"mean_explained", c.mean_explained},
                          {"mean_ranking_share", c.mean_ranking_share},
                          {"explained", per},
                          {"slow", c.slow}});
    if (static_cast<int>(k) >= top) continue;
    std::printf("%-4zu %-34s %5d/%-3zu %13.1f%% ", k + 1, c.term.text().c_str(), c.accepted_on,
                paths.size(), 100 * c.mean_explained);
    for (double e : c.explained) {
      if (std::isfinite(e)) {
        std::printf(" %5.1f%%", 100 * e);
      } else {
        std::printf(" %6s", "-");
      }
    }
    std::printf("\n");
  }
  std::printf("\nverdict: %s\n", season.verdict.c_str());
  if (season.verdict.rfind("add ", 0) == 0) {
    std::string all;
    for (const auto& p : paths) all += (all.empty() ? "" : ",") + p;
    const SeasonCandidate& top_term = season.candidates.front();
    std::printf("to add it:\n  magcomp calibrate --data %s --model %s %s '%s' --out NEW.yaml\n",
                all.c_str(), model_path.c_str(), top_term.slow ? "--slow-term" : "--term",
                top_term.term.text().c_str());
  }
  j["season"] = {{"candidates", candidates}, {"verdict", season.verdict}};
  j["verdict"] = season.verdict;
  if (!json_path.empty()) write_file_atomic(json_path, j.dump(2) + "\n", guard.input_paths());
}

// What diagnose's command line asks for.
struct DiagnoseArgs {
  std::string data, model_path, truth = "mag_1_c", json_path, out, validate, track = "truth";
  std::string attribution;
  int top = 10, rounds = 5;
  double min_share = 0.05;
  bool apply = false, quick = false, choose_lambda = false, no_exchange = false;
  bool no_chance_control = false;
  bool no_look_ahead = false;
  bool no_named_channel = false;
  bool no_refine = false;
  bool keep_factors = false;
  bool no_steady_factors = false;
  bool norm_alone = false;
  bool slow_lines_last = false;
  bool slow_names_kept = false;
  bool tl_as_given = false;
};

// The final model with its held-out error variance, as calibrate writes it (it enters each
// sample's variance: navigate --model-variance, the compensator), written to `out`.
void write_final_model(const LoopResult& r, const std::vector<const FlightData*>& flights,
                       const std::string& truth, const std::string& out,
                       const std::vector<std::string>& inputs) {
  Model final_model = r.model;
  const auto [holdout_var, holdout_rows] = holdout_error_variance_nT2(final_model, flights, truth);
  if (holdout_rows > 0 && std::isfinite(holdout_var))
    final_model.report.holdout_error_variance_nT2 = holdout_var;
  save_model_yaml(final_model, out, inputs);
  std::printf("wrote %s (terms:", out.c_str());
  for (const auto& t : r.model.terms) std::printf(" %s", t.text().c_str());
  std::printf(")\n");
  if (std::isfinite(final_model.report.holdout_error_variance_nT2))
    std::printf(
        "held-out error std %.4g nT against %s on %ld samples of lines not fitted (in "
        "each sample's variance)\n",
        std::sqrt(final_model.report.holdout_error_variance_nT2), truth.c_str(),
        static_cast<long>(holdout_rows));
}

// The command: one flight diagnosed, several ranked together, or the loop (--apply).
void run_diagnose(const DiagnoseArgs& a) {
  if (a.apply && a.out.empty()) throw Error("--apply needs --out (the final model YAML)");
  if (!(a.min_share >= 0 && a.min_share < 1)) throw Error("--min-share: must be in [0, 1)");
  if (a.rounds < 1 || a.rounds > 50) throw Error("--rounds: must be in 1..50");
  if (a.top < 0) throw Error("--top: must be >= 0");
  if (!a.validate.empty() && !a.apply) throw Error("--validate: only with --apply");
  if (!a.out.empty() && !a.apply) throw Error("--out: only with --apply (the final model)");
  if (a.choose_lambda && !a.apply) throw Error("--choose-lambda: only with --apply");
  if (a.no_exchange && !a.apply) throw Error("--no-exchange: only with --apply");
  if (a.no_chance_control && !a.apply) throw Error("--no-chance-control: only with --apply");
  if (a.no_look_ahead && !a.apply) throw Error("--no-look-ahead: only with --apply");
  if (a.no_named_channel && !a.apply) throw Error("--no-named-channel: only with --apply");
  if (a.no_refine && !a.apply) throw Error("--no-refine: only with --apply");
  if (a.keep_factors && !a.apply) throw Error("--keep-factors: only with --apply");
  if (a.no_steady_factors && !a.apply) throw Error("--no-steady-factors: only with --apply");
  if (a.norm_alone && !a.apply) throw Error("--norm-alone: only with --apply");
  if (a.slow_lines_last && !a.apply) throw Error("--slow-lines-last: only with --apply");
  if (a.slow_names_kept && !a.apply) throw Error("--slow-names-kept: only with --apply");
  if (a.tl_as_given && !a.apply) throw Error("--tl-as-given: only with --apply");
  const std::vector<std::string> paths = flight_paths("--data", a.data);
  std::vector<OutputGuard::File> others = {
      {"--model", a.model_path}, {"--validate", a.validate}, {"--attribution", a.attribution}};
  for (const auto& m : map_inputs("--truth", {a.truth})) others.push_back(m);
  OutputGuard guard = guard_for(paths, others);
  guard.add_output("--out", a.out);
  guard.add_output("--json", a.json_path);
  const std::vector<std::string> inputs = guard.input_paths();
  Model model = load_model_yaml(a.model_path);
  // With the map as the reference, it is also the slow stage's (no stinger flies).
  if (nav::names_map(a.truth)) model.fit.reference = a.truth;
  const auto read = [&](const std::string& path) {
    FlightData f = read_flight(path);
    add_map_references(&f, {a.truth, model.fit.reference}, a.track, &model);
    return f;
  };
  DiagnoseOptions options;
  options.full_search = !a.quick;
  options.choose_lambda = a.choose_lambda;
  options.exchange_terms = !a.no_exchange;
  options.chance_control = !a.no_chance_control;
  options.look_ahead = !a.no_look_ahead;
  options.named_channel_term = !a.no_named_channel;
  options.refine_parameters = !a.no_refine;
  options.drop_idle_factors = !a.keep_factors;
  options.steady_factor_products = !a.no_steady_factors;
  options.norm_with_a_term = !a.norm_alone;
  options.slow_lines_first = !a.slow_lines_last;
  options.slow_look_alikes = !a.slow_names_kept;
  options.exact_norm = !a.tl_as_given;
  if (!a.attribution.empty()) options.network_channels = read_network_attribution(a.attribution);
  if (paths.size() > 1 && !a.apply) {
    diagnose_several(model, paths, a.model_path, a.truth, a.json_path, a.top, options, guard, read);
    return;
  }
  // With --apply over several flights, every flight is held: each round diagnoses them all.
  std::vector<FlightData> held_flights;
  for (const auto& path : paths) held_flights.push_back(read(path));
  std::vector<const FlightData*> flights;
  for (const auto& f : held_flights) flights.push_back(&f);
  if (!a.apply) {
    const FlightData& flight = held_flights.front();
    if (!model.fitted()) fit_model(model, {&flight});
    const Diagnosis dx = diagnose(model, flight, a.truth, options);
    guard.check_inputs_unchanged();
    print_diagnosis(model, dx, a.top, a.data, a.model_path);
    print_map_note(a.truth);
    if (a.json_path.empty()) return;
    nlohmann::json j = to_json(dx);
    j["data"] = a.data;
    j["model"] = a.model_path;
    j["truth"] = a.truth;
    write_file_atomic(a.json_path, j.dump(2) + "\n", inputs);
    return;
  }
  std::unique_ptr<FlightData> validation;
  if (!a.validate.empty()) validation = std::make_unique<FlightData>(read(a.validate));
  std::vector<std::pair<std::string, const FlightData*>> named;
  for (const FlightData* f : flights) named.emplace_back("--data", f);
  if (validation) named.emplace_back("--validate", validation.get());
  require_distinct_flights(named, model.scalar);
  const LoopResult r = diagnose_loop(
      model, flights, a.truth, a.rounds, a.min_share, options,
      [&](int round, size_t f, const Diagnosis& dx) {
        print_round_progress(round, f, paths, dx, a.top);
      },
      validation.get());
  guard.check_inputs_unchanged();
  print_rounds_table(r, validation != nullptr, flights.size());
  std::printf("stop: %s\n", r.stop_reason.c_str());
  for (const std::string& w : r.warnings) std::printf("warning: %s\n", w.c_str());
  // Terms the flight barely supports: their channel barely switched where they were fitted.
  const std::vector<TermSupport> support = term_support(r.model, model, flights);
  for (const TermSupport& s : support) {
    const std::string note = support_note(s);
    if (!note.empty()) std::printf("note: %s: %s\n", s.term.c_str(), note.c_str());
    const std::string twins = twins_note(s);
    if (!twins.empty()) std::printf("note: %s: %s\n", s.term.c_str(), twins.c_str());
    const std::string slow = slow_edge_note(s);
    if (!slow.empty()) std::printf("note: %s: %s\n", s.term.c_str(), slow.c_str());
    const std::string trend = time_trend_note(s);
    if (!trend.empty()) std::printf("note: %s: %s\n", s.term.c_str(), trend.c_str());
  }
  print_network_checks(r.last.network, " (checked against the final model)", &r.model);
  write_final_model(r, flights, a.truth, a.out, inputs);
  print_map_note(a.truth);
  if (a.json_path.empty()) return;
  nlohmann::json j = loop_json(r, support);
  j["data"] = a.data;
  j["model"] = a.model_path;
  j["out"] = a.out;
  if (validation) j["validation"] = a.validate;
  write_file_atomic(a.json_path, j.dump(2) + "\n", inputs);
}

}  // namespace

void add_diagnose(CLI::App& app) {
  auto* cmd = app.add_subcommand("diagnose", "rank candidate missing effects on held-out data");
  auto a = std::make_shared<DiagnoseArgs>();
  cmd->add_option("--data", a->data,
                  "flight HDF5 file; several, comma-separated: each diagnosed in turn, the "
                  "candidates ranked across them (with --apply: flights of one aircraft; the "
                  "model is fitted on all of them and every check made on all their held-out "
                  "lines)")
      ->required();
  cmd->add_option("--model", a->model_path, "model YAML (fitted or not)")->required();
  cmd->add_option("--truth", a->truth,
                  "reference field (default mag_1_c), or map:M.h5: the anomaly map along --track "
                  "plus the IGRF and the diurnal (no stinger needed; also the slow stage's "
                  "reference)");
  cmd->add_option("--track", a->track,
                  "with --truth map:M.h5, where the map is read: truth (lat/lon), ins, or filter "
                  "(the navigation filter on the model's anomaly; a fitted model); default truth")
      ->check(CLI::IsMember({"truth", "ins", "filter"}));
  cmd->add_option("--json", a->json_path,
                  "write the diagnosis JSON here (with --apply: the rounds)");
  cmd->add_option("--top", a->top, "rows to print (default 10)");
  cmd->add_flag("--apply", a->apply,
                "run the loop: add the accepted top term while it explains --min-share, refit, "
                "repeat (--rounds); write the final model to --out");
  cmd->add_option("--out", a->out, "with --apply: the final model YAML");
  cmd->add_option("--rounds", a->rounds, "with --apply: at most this many terms added (default 5)");
  cmd->add_option("--min-share", a->min_share,
                  "with --apply: the share of the held-out error a term must explain (0.05)");
  cmd->add_option("--validate", a->validate,
                  "with --apply: another flight of the same aircraft; a term is kept only if it "
                  "also lowers the error there");
  cmd->add_flag(
      "--choose-lambda", a->choose_lambda,
      "with --apply: each round first chooses fit.lambda on the held-out lines (1/10, "
      "1/100 or 1/1000 of the model's, or back to it, if the error falls on both halves)");
  cmd->add_flag("--tl-as-given", a->tl_as_given,
                "with --apply: keep the model's TL as given (by default the first round first "
                "writes it as the exact norm, the `norm` term, and, where the flights record "
                "--truth, fits it against that on the calibration segments, if the held-out "
                "error falls on both halves)");
  cmd->add_flag("--no-exchange", a->no_exchange,
                "with --apply: when no term passes, keep the kept terms as they are (by default "
                "each is taken out in turn and the model without it diagnosed again: a better "
                "term takes its place and the loop goes on)");
  cmd->add_flag("--no-chance-control", a->no_chance_control,
                "with --apply over one flight: keep every kept drift (by default, as the loop "
                "ends, a kept low-pass of 30 s or slower of channels no other term reads "
                "leaves when, with every other term in place, it leaves more than two draws of "
                "the best term of the recorded states read shifted in time leave in turn, "
                "unless it leaves at most the resolution held out and that term the resolution "
                "more: a trend that follows the residual by chance)");
  cmd->add_flag("--no-look-ahead", a->no_look_ahead,
                "with --apply: keep each round's first term that passes (by default, the "
                "runner-up of other channels is looked at one round ahead, and kept when it and "
                "the term that follows it leave less than the first and the term that follows "
                "it)");
  cmd->add_flag("--no-named-channel", a->no_named_channel,
                "with --apply: try the recorded state that predicts most of what remains only as "
                "a learned law (by default, when no term passes, its plain field term is tried "
                "first with the whole model fitted again: the search scores a candidate beside "
                "TL's exact-norm column as the model left it, which hides a channel whose field "
                "TL's coefficients partly took)");
  cmd->add_flag("--no-refine", a->no_refine,
                "with --apply: when no term passes, keep the kept terms' parameters (by default "
                "they are estimated again with every other term in place, alone and beside each "
                "of the first candidates, before any exchange)");
  cmd->add_flag("--keep-factors", a->keep_factors,
                "with --apply: when no term passes, keep every kept product as it is (by default "
                "a product whose factor does not earn its place on the held-out lines is written "
                "without it)");
  cmd->add_flag("--no-steady-factors", a->no_steady_factors,
                "with --apply: when no term passes, keep each kept term as it is (by default a "
                "term whose field scales with a channel the flight holds nearly steady, an engine "
                "speed or a bus, is written as that product when it explains most of what "
                "remains)");
  cmd->add_flag("--norm-alone", a->norm_alone,
                "with --apply: try TL as the exact norm alone only (by default, when no term "
                "passes and the exact norm is refused alone, it is diagnosed and kept together "
                "with the term its diagnosis ranks first if each is needed)");
  cmd->add_flag("--slow-lines-last", a->slow_lines_last,
                "with --apply: size slow terms on the held-out lines only once a round keeps "
                "nothing with them sized on the calibration rows (by default a round whose slow "
                "candidate sized on the lines explains half the held-out error and twice what the "
                "calibration rows' first candidate does tries it first)");
  cmd->add_flag("--slow-names-kept", a->slow_names_kept,
                "with --apply: a kept slow term (a heater, a drift) keeps its channel (by "
                "default, when no term passes, it gives way to a look-alike that leaves less on "
                "the held-out lines with every other term in place, as any kept term does)");
  cmd->add_option("--attribution", a->attribution,
                  "a trained network's attribution (magcomp evaluate --explain --json on a "
                  "flight it never saw): the channels it leans on (10 % or more, at most 3) are "
                  "searched, their products fitted, and their terms judged like every other; "
                  "the output says what became of each");
  cmd->add_flag("--channels-only", a->quick,
                "search only the aircraft's state channels (currents, voltages and any recorded "
                "channel that is not motion, air data or position) and the attitude rates "
                "(faster)");
  cmd->callback([a] { run_diagnose(*a); });
}

}  // namespace magcomp::cli
