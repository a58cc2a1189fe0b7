// magcomp: diagnose's jobs (the term language over the sources), their runs on the workers,
// the products of the strongest sources, and the candidates they become (see search.h).
#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <future>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

bool is_current(const std::string& n) { return n.rfind("cur_", 0) == 0; }
bool is_rate(const std::string& n) {
  return n.size() > 5 && n.compare(n.size() - 5, 5, "_rate") == 0;
}

// The shorthand a plain source is written with: current:X, rate:X, or field:X.
std::string plain_spec(const std::string& x) {
  if (is_electrical(x)) return "current:" + x;
  if (is_rate(x)) return "rate:" + x;
  return "field:" + x;
}

std::string family_of_tl(const std::string& spec) {
  for (const char* f : {"permanent", "induced", "eddy"}) {
    if (spec.rfind(f, 0) == 0 && spec.find(':') == std::string::npos) return f;
  }
  return spec;
}

// Candidate jobs for the sources and the model.
std::vector<Job> make_jobs(const Model& model, const std::vector<std::string>& sources,
                           const std::set<std::string>& rate_recorded) {
  std::vector<Job> jobs;
  std::set<std::string> have(model.terms.begin(), model.terms.end());
  std::set<std::string> shapes;  // a term of the model is re-estimated with ?, not searched again
  for (const TermSpec& t : model.terms) {
    if (const ExprTerm* e = t.expr()) shapes.insert(e->shape());
  }
  std::set<std::string> families;
  for (const auto& t : model.terms) families.insert(family_of_tl(t));
  auto add = [&](const std::string& spec, const std::string& family, const std::string& ch) {
    if (have.count(spec)) return;
    TermSpec term(spec);
    if (const ExprTerm* e = term.expr(); e && shapes.count(e->shape())) return;
    jobs.push_back({std::move(term), family, ch});
  };
  for (const char* f : {"permanent", "induced", "eddy"}) {
    if (!families.count(f)) add(f, "tolles-lawson", "");
  }
  add("second_order", "second order", "");
  add("field:B|decay(?)", "eddy currents that decay", "");
  add("scalar:Bt", "induced field scaling with |B|", "");
  add("scalar:" + model.scalar + "|d", "scalar sensor response", model.scalar);
  for (const std::string& x : sources) {
    add(plain_spec(x), is_rate(x) ? "attitude rate" : "field of a channel", x);
    if (!rate_recorded.count(x))
      add(is_electrical(x) ? "dcurrent:" + x : "field:" + x + "|d", "rate of change", x);
    add("field:" + x + "|lp(?)", "slow response (thermal)", x);
    add("field:" + x + "|delay(?)", "delayed response", x);
    add("scalar:" + x + "|lp(?)", "drift of the reading", x);
    if (!is_electrical(x) && is_aircraft_state(x)) {  // a switch, a valve, a surface, ...
      add("field:" + x + "|step(?)", "a load switched with a state (on above a level of it)", x);
    }
    if (is_current(x)) {
      add("field:" + x + "|pow(2)|lp(?)", "heating (I²) response", x);
      add("field:" + x + "|int", "state (integral of a current)", x);
      add("field:" + x + "|play(?)", "hysteresis (magnetised by the current, with play)", x);
      add("field:" + x + "|sat(?)", "a saturating core (the field levels off with the current)", x);
      add("field:" + x + "|step(?)", "a switched load (on above a level of the current)", x);
    }
  }
  return jobs;
}

// Runs jobs on `threads` workers.
std::vector<Scored> run_jobs(const Search& search, const std::vector<Job>& jobs, int threads) {
  std::vector<Scored> out(jobs.size());
  std::atomic<size_t> next{0};
  auto worker = [&] {
    for (size_t k; (k = next++) < jobs.size();) {
      try {
        out[k] = search.run(jobs[k]);
      } catch (const std::exception& e) {
        out[k].ok = false;
        out[k].note = "candidate '" + jobs[k].term.text() + "' skipped: " + e.what();
      }
    }
  };
  std::vector<std::future<void>> pool;
  for (int t = 1; t < std::max(threads, 1); ++t)
    pool.push_back(std::async(std::launch::async, worker));
  worker();
  for (auto& f : pool) f.get();
  return out;
}

// Each source's best single form: its share of the selection lines' variance, the largest first.
std::vector<std::pair<double, std::string>> strongest_sources(const Model& model,
                                                              const Search& search,
                                                              const std::vector<Job>& jobs,
                                                              const std::vector<Scored>& scored) {
  std::map<std::string, double> best_by_source;
  for (size_t k = 0; k < jobs.size(); ++k) {
    if (!scored[k].ok || jobs[k].channel.empty() || jobs[k].channel == model.scalar) continue;
    auto& b = best_by_source[jobs[k].channel];
    b = std::max(b, share(scored[k].sel, search.base_std[0]));
  }
  std::vector<std::pair<double, std::string>> out;
  for (const auto& [ch, v] : best_by_source) out.emplace_back(v, ch);
  std::sort(out.rbegin(), out.rend());
  return out;
}

// Products of the strongest sources (their best single form explains more than
// accept_fraction on the selection lines): at most 4 sources, so 6 products.
std::vector<Job> product_jobs(const Model& model, const Search& search,
                              const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                              double accept_fraction) {
  std::vector<std::pair<double, std::string>> strongest;
  for (const auto& [v, ch] : strongest_sources(model, search, jobs, scored)) {
    if (v > accept_fraction && ch.find('*') == std::string::npos) strongest.emplace_back(v, ch);
  }
  if (strongest.size() > 4) strongest.resize(4);
  std::vector<Job> products;
  for (size_t a = 0; a < strongest.size(); ++a) {
    for (size_t b = a + 1; b < strongest.size(); ++b) {
      const std::string& x = strongest[a].second;
      const std::string& y = strongest[b].second;
      products.push_back({"field:" + x + "*" + y, "product of two channels", x + "*" + y});
    }
  }
  return products;
}

// Every scored job becomes a candidate (each term once), with its fit counted.
void add_candidates(const std::vector<Job>& jobs, const std::vector<Scored>& scored,
                    const Search& search, Diagnosis* dx) {
  std::set<std::string> seen;
  for (size_t k = 0; k < jobs.size(); ++k) {
    dx->candidates_tried += std::max(scored[k].fits, 1L);
    if (!scored[k].note.empty()) dx->notes.push_back(scored[k].note);
    if (!scored[k].ok || !seen.insert(scored[k].term->spec()).second) continue;
    const TermPtr& term = scored[k].term;
    Candidate c;
    c.term = TermSpec(term);
    c.effect = term->effect();
    c.channel = jobs[k].channel;
    c.family = jobs[k].family;
    c.std_after_nT = scored[k].held;
    c.explained_selection = share(scored[k].sel, search.base_std[0]);
    c.explained_confirmation = share(scored[k].conf, search.base_std[1]);
    c.slow = scored[k].slow;
    c.base_span_share = scored[k].base_span_share;
    if (const auto* e = dynamic_cast<const ExprTerm*>(term.get())) {
      c.estimate = e->size_in_words(scored[k].coef);
      c.parameters = e->parameters();
      c.parameters.emplace_back("gain_nT_per_unit", scored[k].coef.norm());
    }
    if (c.slow) c.estimate += (c.estimate.empty() ? "" : ", ") + std::string("slow stage");
    dx->candidates.push_back(c);
  }
}

}  // namespace magcomp::diagnose_search
