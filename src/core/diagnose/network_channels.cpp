// magcomp: diagnose reading a trained network's attribution: the channels the network leans on
// searched, their products fitted, and what became of each (DiagnoseOptions::network_channels).
#include <algorithm>
#include <cmath>
#include <set>

#include "magcomp/core/diagnose/residual_floor.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp {

std::vector<NetworkChannel> network_leads(std::vector<NetworkChannel> ranked) {
  ranked.erase(std::remove_if(ranked.begin(), ranked.end(),
                              [](const NetworkChannel& c) {
                                return c.channel.empty() || !(c.share >= kNetworkMinShare);
                              }),
               ranked.end());
  std::stable_sort(
      ranked.begin(), ranked.end(),
      [](const NetworkChannel& a, const NetworkChannel& b) { return a.share > b.share; });
  std::vector<NetworkChannel> out;
  std::set<std::string> seen;
  for (const NetworkChannel& c : ranked) {
    if (out.size() == kNetworkChannels) break;
    if (seen.insert(c.channel).second) out.push_back(c);
  }
  return out;
}

std::vector<std::string> term_channels(const TermSpec& term) {
  if (const ExprTerm* e = term.expr()) return e->required_fields();
  return {};
}

namespace diagnose_search {
namespace {

bool contains(const std::vector<std::string>& v, const std::string& x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

// The unordered pair of a product's two channels ("a*b" and "b*a" are one product).
std::pair<std::string, std::string> pair_of(const std::string& a, const std::string& b) {
  return a < b ? std::make_pair(a, b) : std::make_pair(b, a);
}

}  // namespace

void add_network_sources(const std::vector<std::string>& all,
                         const std::vector<NetworkChannel>& leads,
                         std::vector<std::string>* aircraft_sources) {
  for (const NetworkChannel& c : leads) {
    if (contains(*aircraft_sources, c.channel) || !contains(all, c.channel) ||
        is_position_channel(c.channel) || is_earth_frame_velocity(c.channel))
      continue;
    aircraft_sources->push_back(c.channel);
  }
}

std::vector<Job> network_product_jobs(const Model& model, const Search& search,
                                      const std::vector<Job>& jobs,
                                      const std::vector<Scored>& scored,
                                      const std::vector<NetworkChannel>& leads,
                                      const std::vector<std::string>& aircraft_sources,
                                      const std::vector<Job>& taken) {
  if (leads.empty()) return {};
  std::set<std::pair<std::string, std::string>> have;
  for (const Job& j : taken) {
    const std::vector<std::string> ch = term_channels(j.term);
    if (ch.size() == 2) have.insert(pair_of(ch[0], ch[1]));
  }
  std::vector<std::string> partners;
  for (const NetworkChannel& c : leads)
    if (contains(aircraft_sources, c.channel)) partners.push_back(c.channel);
  const size_t n_leads = partners.size();
  for (const auto& [v, ch] : strongest_sources(model, search, jobs, scored)) {
    if (partners.size() == n_leads + kNetworkPartners) break;
    if (ch.find('*') == std::string::npos && !contains(partners, ch)) partners.push_back(ch);
  }
  std::vector<Job> out;
  for (size_t a = 0; a < n_leads; ++a) {
    for (size_t b = a + 1; b < partners.size(); ++b) {
      const std::string& x = partners[a];
      const std::string& y = partners[b];
      if (!have.insert(pair_of(x, y)).second) continue;
      out.push_back(
          {"field:" + x + "*" + y, "product of a channel the network leans on", x + "*" + y});
    }
  }
  return out;
}

void mark_network_share(const std::vector<NetworkChannel>& leads,
                        std::vector<Candidate>* candidates) {
  if (leads.empty()) return;
  for (Candidate& c : *candidates) {
    c.network_share = 0.0;
    const std::vector<std::string> ch = term_channels(c.term);
    for (const NetworkChannel& l : leads)
      if (contains(ch, l.channel)) c.network_share += l.share;
  }
}

std::vector<NetworkCheck> network_checks(const FlightData& data,
                                         const std::vector<std::string>& all,
                                         const std::vector<NetworkChannel>& leads,
                                         const std::vector<Candidate>& candidates,
                                         const std::vector<std::string>& aircraft_sources) {
  std::vector<NetworkCheck> out;
  if (leads.empty()) return out;
  for (const NetworkChannel& l : leads) {
    NetworkCheck c;
    c.channel = l.channel;
    c.share = l.share;
    c.searched = contains(aircraft_sources, l.channel);
    if (!data.has(l.channel)) {
      c.why_not = "not in the data";
    } else if (is_position_channel(l.channel)) {
      c.why_not =
          "a position or trajectory channel: leakage of the map or the trajectory, "
          "never a term";
    } else if (!c.searched && is_earth_frame_velocity(l.channel)) {
      c.why_not =
          "an earth-frame velocity (the trajectory's heading): leakage of the map or of "
          "TL's heading error, searched only by the full search";
    } else if (!contains(all, l.channel)) {
      c.why_not = "not a source here (constant, more than 10 % NaN, a sensor or the reference)";
    }
    // Candidates are ranked: accepted first, the best first. The channel's own terms speak for
    // it, unless a term with another channel (a product) is accepted above them.
    const Candidate* own = nullptr;
    const Candidate* any = nullptr;
    for (const Candidate& k : candidates) {
      const std::vector<std::string> ch = term_channels(k.term);
      if (!contains(ch, l.channel)) continue;
      if (!any) any = &k;
      if (ch.size() == 1) {
        own = &k;
        break;
      }
    }
    const Candidate* best = own && !(any && any->accepted && !own->accepted) ? own : any;
    if (best) {
      c.best_term = best->term.text();
      c.explained_selection = best->explained_selection;
      c.explained_confirmation = best->explained_confirmation;
      c.accepted = best->accepted;
    }
    out.push_back(c);
  }
  return out;
}

}  // namespace diagnose_search
}  // namespace magcomp
