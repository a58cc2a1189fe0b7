// magcomp: diagnose: one round of the search for a missing effect, its steps in order (the steps
// in search.h).
#include "magcomp/core/diagnose/diagnose.h"

#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "magcomp/core/diagnose/channel_noise.h"
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

std::vector<std::string> source_fields(const Model& model, const FlightData& data,
                                       const std::string& truth, bool full_search,
                                       std::vector<std::string>* notes) {
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
      continue;
    }
    out.push_back(name);
  }
  if (notes && !noise_only.empty())
    notes->push_back(
        "channels that record a constant and their white noise only (their 10 s "
        "means vary no more than that noise gives), skipped: " +
        noise_only);
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
  const std::vector<std::string> sources =
      source_fields(model, data, truth_name, options.full_search, &dx.notes);
  data.drop_mapped_pages();
  // Position and trajectory channels are no source of aircraft field: never a term (the
  // explainable share still reads them, to report leakage).
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
  std::vector<Job> jobs = make_jobs(model, aircraft_sources);
  std::vector<Scored> scored = run_jobs(search, jobs, options.threads);
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
    std::vector<Job> grown = refined_jobs(model, search, jobs, scored, &seen);
    for (int level = 0; level < 2 && !grown.empty(); ++level) {
      std::vector<Scored> more = run_jobs(search, grown, options.threads);
      for (auto& x : more)
        if (x.ok && at_slow_edge(*x.term, search)) x.ok = false;
      jobs.insert(jobs.end(), grown.begin(), grown.end());
      scored.insert(scored.end(), more.begin(), more.end());
      grown = level == 0 ? refined_jobs(model, search, grown, more, &seen) : std::vector<Job>{};
    }
  }
  data.drop_mapped_pages();
  add_candidates(jobs, scored, search, &dx);
  add_lag_candidate(model, data, search, &dx);
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
  data.drop_mapped_pages();
  dx.verdict = verdict_of(dx, options.resolution_nT);
  return dx;
}

}  // namespace magcomp
