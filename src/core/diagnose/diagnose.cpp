// magcomp: diagnose: one round of the search for a missing effect, its steps in order (the steps
// in search.h).
#include "magcomp/core/diagnose/diagnose.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <string>
#include <vector>

#include "magcomp/core/diagnose/channel_noise.h"
#include "magcomp/core/diagnose/channel_twins.h"
#include "magcomp/core/diagnose/recorded_rates.h"
#include "magcomp/core/diagnose/residual_floor.h"
#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp {

using diagnose_search::is_rate;

// How much a term says: its sources and transforms (a shorthand or TL family counts 1).
int term_complexity(const TermSpec& term) {
  const ExprTerm* e = term.expr();
  if (!e) return 1;
  int n = static_cast<int>(e->signal().sources.size() + e->signal().transforms.size());
  for (const auto& t : e->signal().transforms) n += t.has_param();
  return n;
}

double slowest_low_pass_s(const TermSpec& term) {
  double tau_s = 0.0;
  if (const ExprTerm* e = term.expr())
    for (const Transform& x : e->signal().transforms)
      if (x.kind == TransformKind::LowPass && x.param > tau_s) tau_s = x.param;
  return tau_s;
}

std::vector<std::string> source_fields(const Model& model, const FlightData& data,
                                       const std::string& truth, bool full_search,
                                       std::vector<std::string>* notes,
                                       std::vector<std::string>* rails) {
  std::vector<std::string> out;
  std::string noise_only;
  for (const std::string& name : data.names()) {
    if (is_bookkeeping_channel(name) || name.rfind("mag_", 0) == 0 || name.rfind("flux_", 0) == 0 ||
        name == truth || name == model.fit.reference || name == "diurnal" ||
        name.rfind("ogs_", 0) == 0 || name == "drape" || name.front() == '~') {
      continue;
    }
    if (!full_search && !is_aircraft_state(name) && !is_rate(name)) continue;
    const FlightData::Column x = data.column(name);
    double lo = INFINITY, hi = -INFINITY;
    Eigen::Index finite = 0;
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      if (std::isfinite(x[i])) {
        lo = std::min(lo, x[i]);
        hi = std::max(hi, x[i]);
        ++finite;
      }
    }
    if (!(hi > lo)) {
      if (notes) notes->push_back("channel '" + name + "' is constant (or all NaN); skipped");
      continue;
    }
    if (finite < x.size() * 9 / 10) {
      if (notes) notes->push_back("channel '" + name + "' is more than 10 % NaN; skipped");
      continue;
    }
    // A rail that reads a constant plus its noise: whatever a term of it fits is that noise.
    if (records_noise_only(x, data.dt_s())) {
      noise_only += (noise_only.empty() ? "" : ", ") + name;
      if (rails) rails->push_back(name);
      continue;
    }
    out.push_back(name);
  }
  if (notes && !noise_only.empty()) {
    char share[120];
    std::snprintf(share, sizeof(share),
                  "searched only for a term explaining %.0f %% of the held-out variance on both "
                  "splits",
                  100 * kRailShare);
    notes->push_back(
        "channels that record a constant and their white noise only (their 10 s "
        "means vary no more than that noise gives), " +
        std::string(rails ? share : "skipped") + ": " + noise_only);
  }
  return out;
}

namespace {

// The model to diagnose: the reference checked, and a template's free parameters estimated.
Model prepared_model(const Model& model_in, const FlightData& data, const std::string& truth_name) {
  if (!data.has(truth_name)) {
    throw Error(data.source() + ": reference field '" + truth_name + "' not found");
  }
  if (!data.column(truth_name).array().isFinite().any()) {
    throw Error(data.source() + ": reference field '" + truth_name + "' holds no finite sample");
  }
  Model model = model_in;
  for (const auto& t : model.terms) {
    if (t.text().find('?') != std::string::npos) {
      fit_model(model, {&data});
      break;
    }
  }
  return model;
}

// A candidate reading a rail stays only where it explains kRailShare of the held-out variance on
// both splits: nothing later (the loop's own rounds) can then take a chance fit of a rail's noise.
void drop_weak_rail_terms(const std::vector<std::string>& rails,
                          std::vector<Candidate>* candidates) {
  if (rails.empty()) return;
  const std::set<std::string> rail_set(rails.begin(), rails.end());
  candidates->erase(std::remove_if(candidates->begin(), candidates->end(),
                                   [&](const Candidate& c) {
                                     const std::vector<std::string> xs = term_channels(c.term);
                                     const bool reads_rail = std::any_of(
                                         xs.begin(), xs.end(),
                                         [&](const auto& x) { return rail_set.count(x) > 0; });
                                     return reads_rail && !(c.explained_selection >= kRailShare &&
                                                            c.explained_confirmation >= kRailShare);
                                   }),
                    candidates->end());
}

// Each rail's drift of the reading (its recorded wander, low-passed, added to the scalar; a
// field term of a rail is mostly its level times TL's own columns), scored, and kept among the
// jobs only where it explains kRailShare of the held-out variance on both splits: a weaker one
// never leads the products or the grammar (its fits are counted all the same).
void add_strong_rail_jobs(const Model& model, const diagnose_search::Search& search,
                          const std::vector<std::string>& rails, int threads,
                          std::vector<diagnose_search::Job>* jobs,
                          std::vector<diagnose_search::Scored>* scored, Diagnosis* dx) {
  using namespace diagnose_search;
  std::vector<Job> rail_jobs;
  for (Job& j : make_jobs(model, rails)) {
    const std::string& spec = j.term.text();
    if (spec.rfind("scalar:", 0) == 0 && spec.find("|lp(?)") != std::string::npos)
      rail_jobs.push_back(std::move(j));
  }
  if (rail_jobs.empty()) return;
  const std::vector<Scored> rail_scored = run_jobs(search, rail_jobs, threads);
  for (size_t k = 0; k < rail_jobs.size(); ++k) {
    const Scored& x = rail_scored[k];
    if (x.ok && share(x.sel, search.base_std[0]) >= kRailShare &&
        share(x.conf, search.base_std[1]) >= kRailShare) {
      jobs->push_back(rail_jobs[k]);
      scored->push_back(x);
    } else {
      dx->candidates_tried += std::max(x.fits, 1L);
    }
  }
}

}  // namespace

Diagnosis diagnose(const Model& model_in, const FlightData& data, const std::string& truth_name,
                   const DiagnoseOptions& options) {
  using namespace diagnose_search;
  const Model model = prepared_model(model_in, data, truth_name);
  Diagnosis dx;
  // Each step copies the columns it reads: between steps the file's pages need not stay
  // resident (they are mapped again when read).
  const Search search(model, data, truth_name, &dx, options.slow_terms_on_lines,
                      options.thresholds_on_selection, options.second_order_on_lines);
  std::vector<std::string> rails;
  const std::vector<std::string> sources =
      source_fields(model, data, truth_name, options.full_search, &dx.notes,
                    options.search_rails ? &rails : nullptr);
  data.drop_mapped_pages();
  // Position and trajectory channels are no source of aircraft field: never a term (the
  // explainable share still reads them, to report leakage). The rails are searched by their own
  // terms (kept only above kRailShare, below), not screened in products, not read by the
  // explainable share or the floor.
  std::vector<std::string> aircraft_sources;
  for (const auto& s : sources)
    if (!is_position_channel(s)) aircraft_sources.push_back(s);
  const std::vector<NetworkChannel> leads = network_leads(options.network_channels);
  // The full search's sources (the search's own on a full search), read once when a network
  // names channels: where they may come from, and why one is not searched.
  std::vector<std::string> all_sources;
  if (!leads.empty())
    all_sources =
        options.full_search ? sources : source_fields(model, data, truth_name, true, nullptr);
  add_network_sources(all_sources, leads, &aircraft_sources);
  std::set<std::string> rate_recorded;
  for (const RecordedRate& r : recorded_rates(data, aircraft_sources)) {
    rate_recorded.insert(r.channel);
    char line[300];
    std::snprintf(line, sizeof(line),
                  "the rate of change of '%s' is recorded as '%s' (r = %.4f over %.0f s means): "
                  "searched as '%s'",
                  r.channel.c_str(), r.rate.c_str(), r.correlation, kTwinWindow_s, r.rate.c_str());
    dx.notes.push_back(line);
  }
  std::vector<Job> jobs = make_jobs(model, aircraft_sources, rate_recorded);
  std::vector<Scored> scored = run_jobs(search, jobs, options.threads);
  add_strong_rail_jobs(model, search, rails, options.threads, &jobs, &scored, &dx);
  std::vector<Job> products = product_jobs(model, search, jobs, scored, options.accept_fraction);
  if (options.full_search) {
    const std::vector<Job> screened =
        screened_products(search, aircraft_sources, products, kScreenedProducts, options.threads);
    products.insert(products.end(), screened.begin(), screened.end());
  }
  {
    const std::vector<Job> named =
        network_product_jobs(model, search, jobs, scored, leads, aircraft_sources, products);
    products.insert(products.end(), named.begin(), named.end());
  }
  if (!products.empty()) {
    std::vector<Scored> more = run_jobs(search, products, options.threads);
    jobs.insert(jobs.end(), products.begin(), products.end());
    scored.insert(scored.end(), more.begin(), more.end());
  }
  {  // the grammar search, best-first: two levels
    std::set<std::string> seen;
    for (const auto& j : jobs) seen.insert(j.term.text());
    for (const auto& x : scored)
      if (x.term) seen.insert(x.term->spec());
    std::vector<Job> grown = refined_jobs(model, search, jobs, scored, &seen, rate_recorded);
    for (int level = 0; level < 2 && !grown.empty(); ++level) {
      std::vector<Scored> more = run_jobs(search, grown, options.threads);
      for (auto& x : more)
        if (x.ok && at_slow_edge(*x.term, search)) x.ok = false;
      jobs.insert(jobs.end(), grown.begin(), grown.end());
      scored.insert(scored.end(), more.begin(), more.end());
      grown = level == 0 ? refined_jobs(model, search, grown, more, &seen, rate_recorded)
                         : std::vector<Job>{};
    }
  }
  data.drop_mapped_pages();
  add_candidates(jobs, scored, search, &dx);
  add_lag_candidate(model, data, search, &dx);
  drop_weak_rail_terms(rails, &dx.candidates);
  judge_and_rank(search, options, &dx.candidates);
  for (size_t k = 0, sized = 0; k < dx.candidates.size() && sized < kSizedCandidates; ++k) {
    if (!dx.candidates[k].accepted) break;
    size_uncertainty(search, &dx.candidates[k]);
    ++sized;
  }
  mark_network_share(leads, &dx.candidates);
  dx.network = network_checks(data, all_sources, leads, dx.candidates, aircraft_sources);
  data.drop_mapped_pages();
  dx.associations = residual_associations(data, search.held, search.e0, search.line, truth_name);
  data.drop_mapped_pages();
  if (options.explainable_share) {
    dx.explainable =
        remaining_share(data, search, sources, dx.baseline_std_nT, options.resolution_nT);
  }
  if (options.joint_selection)
    dx.joint = joint_selection(search, dx.candidates, dx.explainable, options);
  dx.floor = floor_of(data, search, sources);
  dx.one_half = one_half_term(data, search, dx.candidates, options.resolution_nT);
  data.drop_mapped_pages();
  dx.verdict = verdict_of(dx, options.resolution_nT);
  return dx;
}

}  // namespace magcomp
