// magcomp command line: a network's attribution read back for diagnose (network_attribution.h).
#include "network_attribution.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

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

}  // namespace magcomp::cli
