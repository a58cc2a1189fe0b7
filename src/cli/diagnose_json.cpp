// magcomp CLI: diagnose's JSON (diagnose_json.h).
#include "diagnose_json.h"

#include <algorithm>
#include <cmath>

#include "common.h"
#include "network_attribution.h"

namespace magcomp::cli {

nlohmann::json to_json(const Diagnosis& dx) {
  nlohmann::json j;
  j["split"] = dx.split;
  j["baseline_std_nT"] = dx.baseline_std_nT;
  j["baseline_selection_std_nT"] = dx.baseline_selection_std_nT;
  j["baseline_confirmation_std_nT"] = dx.baseline_confirmation_std_nT;
  j["selection_lines"] = dx.selection_lines;
  j["confirmation_lines"] = dx.confirmation_lines;
  j["heldout_samples"] = dx.heldout_samples;
  j["fit_samples"] = dx.fit_samples;
  j["candidates_tried"] = dx.candidates_tried;
  j["candidates"] = nlohmann::json::array();
  for (const auto& c : dx.candidates) {
    nlohmann::json p = nlohmann::json::object();
    for (const auto& [k, v] : c.parameters) p[k] = v;
    j["candidates"].push_back({{"term", c.term.text()},
                               {"effect", c.effect},
                               {"channel", c.channel},
                               {"family", c.family},
                               {"std_after_nT", c.std_after_nT},
                               {"explained_fraction", c.explained_fraction},
                               {"explained_selection", c.explained_selection},
                               {"explained_confirmation", c.explained_confirmation},
                               {"accepted", c.accepted},
                               {"slow", c.slow},
                               {"chosen_on_confirmation", c.chosen_on_confirmation},
                               {"estimate", c.estimate},
                               {"parameters", p},
                               {"network_share", c.network_share}});
    // Where it is measured (a band-pass term): absent for a slow term, never null.
    if (std::isfinite(c.base_span_share))
      j["candidates"].back()["base_span_share"] = c.base_span_share;
    // How well its fit rows size it (the first accepted candidates): absent when not computed.
    if (std::isfinite(c.size_nT) && std::isfinite(c.size_sigma_nT)) {
      auto& cj = j["candidates"].back();
      cj["size_nT"] = c.size_nT;
      cj["size_sigma_nT"] = c.size_sigma_nT;
      cj["coefficient_sigma"] = c.coefficient_sigma;
      if (c.switches >= 0) {
        cj["switches"] = c.switches;
        cj["switches_channel"] = c.switches_channel;
      }
    }
  }
  const ExplainableShare& x = dx.explainable;
  nlohmann::json e;
  e["computed"] = x.computed;
  e["share"] = x.share;
  e["uncertainty"] = x.uncertainty;
  e["noise_floor"] = x.noise_floor;
  e["within_noise"] = x.within_noise;
  e["channels"] = nlohmann::json::array();
  for (const auto& [ch, v] : x.channels) e["channels"].push_back({{"channel", ch}, {"share", v}});
  e["time_scales"] = nlohmann::json::object();
  for (const auto& [band, v] : x.time_scales) e["time_scales"][band] = v;
  e["lines"] = nlohmann::json::array();
  for (const auto& [l, v] : x.lines) e["lines"].push_back({{"line", l}, {"fraction", v}});
  j["explainable_share"] = e;
  const ResidualFloor& f = dx.floor;
  j["residual_floor"] = {{"computed", f.computed},
                         {"residual_std_nT", f.residual_std_nT},
                         {"floor_nT", f.floor_nT},
                         {"band_lo_hz", f.band_lo_hz},
                         {"segments", f.segments},
                         {"amplitude_channel", f.amplitude_channel},
                         {"amplitude_correlation", f.amplitude_correlation},
                         {"amplitude_windows", f.amplitude_windows},
                         {"floor_channel", f.floor_channel},
                         {"floor_correlation", f.floor_correlation}};
  j["verdict"] = dx.verdict;
  if (!dx.joint.terms.empty()) {
    const JointSet& js = dx.joint;
    nlohmann::json t = nlohmann::json::array();
    for (const TermSpec& term : js.terms) t.push_back(term.text());
    j["joint_set"] = {{"terms", t},
                      {"selection_std_nT", js.selection_std_nT},
                      {"confirmation_std_nT", js.confirmation_std_nT},
                      {"heldout_std_nT", js.heldout_std_nT},
                      {"alone_heldout_std_nT", js.alone_std_nT},
                      {"stability", js.stability},
                      {"pool_size", js.pool_size}};
    if (!js.best_single.empty()) {
      j["joint_set"]["best_single"] = js.best_single;
      j["joint_set"]["best_single_heldout_std_nT"] = js.best_single_std_nT;
    }
  }
  if (!dx.one_half.term.empty()) {
    const OneHalfTerm& h = dx.one_half;
    j["one_half_term"] = {{"term", h.term},
                          {"channel", h.channel},
                          {"half", h.half == 0 ? "selection" : "confirmation"},
                          {"explained", h.explained},
                          {"lines", h.lines}};
  }
  j["associations"] = nlohmann::json::array();
  for (const auto& a : dx.associations) {
    j["associations"].push_back({{"channel", a.channel},
                                 {"pearson", a.pearson},
                                 {"spearman", a.spearman},
                                 {"mutual_information_bits", a.mutual_information_bits}});
  }
  if (!dx.network.empty()) j["network"] = network_json(dx.network);
  j["notes"] = dx.notes;
  return j;
}

nlohmann::json twins_json(const std::vector<ChannelTwin>& twins) {
  nlohmann::json out = nlohmann::json::array();
  for (const ChannelTwin& t : twins)
    out.push_back({{"channel", t.channel}, {"twin", t.twin}, {"correlation", t.correlation}});
  return out;
}

nlohmann::json time_trends_json(const std::vector<TimeTrend>& trends) {
  nlohmann::json out = nlohmann::json::array();
  for (const TimeTrend& t : trends) out.push_back({{"channel", t.channel}, {"share", t.share}});
  return out;
}

nlohmann::json loop_json(const LoopResult& r, const std::vector<TermSupport>& support) {
  nlohmann::json j;
  j["rounds"] = nlohmann::json::array();
  for (const auto& lr : r.rounds) {
    j["rounds"].push_back({{"round", lr.round},
                           {"added", lr.added},
                           {"black_box", lr.black_box},
                           {"explained_fraction", lr.explained},
                           {"heldout_std_nT", lr.heldout_std_nT},
                           {"all_std_nT", lr.all_std_nT},
                           {"fom_nT", json_figure(lr.fom_nT)}});
    auto& jr = j["rounds"].back();
    jr["validation_std_nT"] = json_figure(lr.validation_std_nT);
    jr["calibration_std_nT"] = json_figure(lr.calibration_std_nT);
    jr["flights_heldout_std_nT"] = nlohmann::json::array();
    for (double v : lr.flight_heldout_std_nT)
      jr["flights_heldout_std_nT"].push_back(json_figure(v));
    jr["rejected"] = nlohmann::json::array();
    for (const auto& [term, why] : lr.rejected)
      jr["rejected"].push_back({{"term", term}, {"why", why}});
    jr["together"] = lr.together;
    jr["slow_on_lines"] = lr.slow_on_lines;
    jr["lambda"] = json_figure(lr.lambda);
    jr["regularisation"] = lr.regularisation;
    jr["model_change"] = lr.model_change;
    jr["flight_halves"] = lr.flight_halves;
    if (lr.flight_halves)
      jr["flight_halves_before_heldout_std_nT"] = {json_figure(lr.flight_halves_before_nT[0]),
                                                   json_figure(lr.flight_halves_before_nT[1]),
                                                   json_figure(lr.flight_halves_before_nT[2])};
    jr["in_place_of"] = lr.in_place_of;
    if (!lr.in_place_of.empty()) jr["in_place_of_span_share"] = lr.in_place_of_span_share;
    jr["alone_heldout_std_nT"] = lr.alone_std_nT;
    jr["removed"] = nlohmann::json::array();
    for (const auto& [term, why] : lr.removed)
      jr["removed"].push_back({{"term", term}, {"why", why}});
    jr["replaced"] = nlohmann::json::array();
    for (const auto& [term, why] : lr.replaced)
      jr["replaced"].push_back({{"term", term}, {"why", why}});
    jr["look_alikes"] = nlohmann::json::array();
    for (const auto& [term, std_nT] : lr.look_alikes) {
      nlohmann::json entry = {{"term", term}, {"heldout_std_nT", std_nT}};
      for (const LookAlikeRatio& q : lr.look_alike_ratios) {
        if (q.term != term) continue;
        entry["ratio_follows"] = {{"kept_channel", q.kept_channel},
                                  {"look_alike_channel", q.alike_channel},
                                  {"channel", q.channel},
                                  {"correlation", json_figure(q.correlation)},
                                  {"relative_std", json_figure(q.relative_std)}};
      }
      jr["look_alikes"].push_back(std::move(entry));
    }
    jr["steady_factors"] = nlohmann::json::array();
    for (const auto& [channel, relative] : lr.steady_factors)
      jr["steady_factors"].push_back({{"channel", channel}, {"relative_std", relative}});
  }
  j["stop"] = r.stop_reason;
  j["warnings"] = r.warnings;
  j["support"] = nlohmann::json::array();
  for (const TermSupport& s : support) {
    j["support"].push_back({{"term", s.term},
                            {"channel", s.channel},
                            {"switches", s.switches},
                            {"size_nT", json_figure(s.size_nT)},
                            {"size_sigma_nT", json_figure(s.size_sigma_nT)},
                            {"note", support_note(s)},
                            {"slowest_time_constant_s", json_figure(s.slowest_time_constant_s)},
                            {"slow_edge_note", slow_edge_note(s)},
                            {"twins", twins_json(s.twins)},
                            {"time_trends", time_trends_json(s.time_trends)},
                            {"time_trend_note", time_trend_note(s)}});
  }
  j["last_diagnosis"] = to_json(r.last);
  if (!r.last.network.empty()) j["network"] = network_json(r.last.network, &r.model);
  return j;
}

}  // namespace magcomp::cli
