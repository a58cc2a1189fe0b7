// magcomp command line: a network's attribution read back for diagnose, and what became of its
// channels (network_attribution.h).
#include "network_attribution.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

#include "common.h"
#include "magcomp/core/error.h"

namespace magcomp::cli {
namespace {

// One attribution object's channel shares, checked entry by entry; `where` names it in errors.
std::map<std::string, double> channel_shares(const std::string& path, const nlohmann::json& a,
                                             const std::string& where) {
  if (!a.is_object() || !a.contains("channels") || !a["channels"].is_array())
    throw Error(path + ": " + where + ".channels: missing or not an array");
  std::map<std::string, double> out;
  const nlohmann::json& channels = a["channels"];
  for (size_t k = 0; k < channels.size(); ++k) {
    const std::string at = where + ".channels[" + std::to_string(k) + "]";
    const nlohmann::json& c = channels[k];
    if (!c.is_object() || !c.contains("channel") || !c["channel"].is_string() ||
        c["channel"].get<std::string>().empty())
      throw Error(path + ": " + at + ".channel: missing or not a channel name");
    if (!c.contains("share") || !c["share"].is_number())
      throw Error(path + ": " + at + ".share: missing or not a number");
    const double share = c["share"].get<double>();
    if (!(share >= 0.0 && share <= 1.0))
      throw Error(path + ": " + at + ".share: " + std::to_string(share) + " is not in [0, 1]");
    out[c["channel"].get<std::string>()] += share;
  }
  return out;
}

// The final model's terms (band-pass and slow) that read `channel`.
std::vector<std::string> terms_reading(const Model& model, const std::string& channel) {
  std::vector<std::string> out;
  std::vector<TermSpec> all(model.terms.begin(), model.terms.end());
  for (const std::string& t : model.slow_terms) all.emplace_back(t);
  for (const TermSpec& t : all) {
    const std::vector<std::string> ch = term_channels(t);
    if (std::find(ch.begin(), ch.end(), channel) != ch.end()) out.push_back(t.text());
  }
  return out;
}

}  // namespace

std::vector<NetworkChannel> read_network_attribution(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot be read (--attribution)");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": not JSON (--attribution): " + e.what());
  }
  std::vector<std::pair<std::string, const nlohmann::json*>> found;
  if (j.is_object() && j.contains("channels")) {
    found.emplace_back("attribution", &j);
  } else if (j.is_object() && j.contains("attribution")) {
    found.emplace_back("attribution", &j["attribution"]);
  } else if (j.is_object() && j.contains("flights") && j["flights"].is_array()) {
    for (size_t f = 0; f < j["flights"].size(); ++f) {
      const nlohmann::json& flight = j["flights"][f];
      if (flight.is_object() && flight.contains("attribution"))
        found.emplace_back("flights[" + std::to_string(f) + "].attribution",
                           &flight["attribution"]);
    }
  }
  if (found.empty())
    throw Error(path +
                ": no attribution (write one with magcomp evaluate --explain --json on a "
                "flight the network never saw)");
  std::map<std::string, double> sum;
  for (const auto& [where, a] : found)
    for (const auto& [channel, share] : channel_shares(path, *a, where)) sum[channel] += share;
  std::vector<NetworkChannel> out;
  for (const auto& [channel, share] : sum)
    out.push_back({channel, share / static_cast<double>(found.size())});
  std::stable_sort(out.begin(), out.end(), [](const NetworkChannel& a, const NetworkChannel& b) {
    return a.share > b.share;
  });
  return out;
}

void print_network_checks(const std::vector<NetworkCheck>& network, const std::string& after,
                          const Model* final_model) {
  if (network.empty()) return;
  std::printf("\nthe network leans on (--attribution)%s:\n", after.c_str());
  for (const NetworkCheck& c : network) {
    std::printf("  %-14s %3.0f %%: ", c.channel.c_str(), 100 * c.share);
    if (final_model) {
      std::string names;
      for (const std::string& t : terms_reading(*final_model, c.channel))
        names += (names.empty() ? "" : ", ") + t;
      if (!names.empty()) {
        std::printf("the final model names it (%s)\n", names.c_str());
        continue;
      }
      std::printf("no term of the final model reads it; ");
    }
    if (!c.why_not.empty()) {
      std::printf("not searched: %s\n", c.why_not.c_str());
    } else if (c.best_term.empty()) {
      std::printf("no candidate reads it\n");
    } else {
      std::printf(
          "%s%s explains %.1f %% of the selection lines and %.1f %% of the confirmation "
          "lines: %s\n",
          final_model ? "in the last round " : "", c.best_term.c_str(), 100 * c.explained_selection,
          100 * c.explained_confirmation,
          c.accepted ? "accepted" : "rejected (the held-out lines decide)");
    }
  }
}

nlohmann::json network_json(const std::vector<NetworkCheck>& network, const Model* final_model) {
  nlohmann::json out = nlohmann::json::array();
  for (const NetworkCheck& c : network) {
    out.push_back({{"channel", c.channel},
                   {"share", c.share},
                   {"searched", c.searched},
                   {"why_not", c.why_not},
                   {"best_term", c.best_term},
                   {"explained_selection", json_figure(c.explained_selection)},
                   {"explained_confirmation", json_figure(c.explained_confirmation)},
                   {"accepted", c.accepted}});
    if (final_model) out.back()["final_terms"] = terms_reading(*final_model, c.channel);
  }
  return out;
}

}  // namespace magcomp::cli
