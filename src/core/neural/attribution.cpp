// magcomp: permutation importance of a neural stage's inputs (see attribution.h).
#include "magcomp/core/neural/attribution.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>

#include "magcomp/core/error.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/neural/features.h"

namespace magcomp {
namespace {

// Squared error per row against the target, on the scored rows.
Eigen::VectorXd squared_errors(const Eigen::VectorXd& y_nT, const Eigen::VectorXd& target_nT,
                               const std::vector<Eigen::Index>& rows) {
  Eigen::VectorXd e(static_cast<Eigen::Index>(rows.size()));
  for (size_t r = 0; r < rows.size(); ++r) {
    const double d = y_nT[rows[r]] - target_nT[rows[r]];
    e[static_cast<Eigen::Index>(r)] = d * d;
  }
  return e;
}

}  // namespace

std::vector<std::vector<std::pair<std::string, double>>> look_alike_channels(
    const FlightData& data, const std::vector<std::string>& channels,
    const std::vector<Eigen::Index>& rows, double min_abs_r) {
  const size_t c = channels.size();
  std::vector<std::vector<std::pair<std::string, double>>> out(c);
  std::vector<Eigen::VectorXd> x(c);  // empty: the data lacks the channel
  for (size_t k = 0; k < c; ++k)
    if (data.has(channels[k])) x[k] = data.column(channels[k]);
  for (size_t a = 0; a < c; ++a) {
    for (size_t b = a + 1; b < c; ++b) {
      if (x[a].size() == 0 || x[b].size() == 0) continue;
      double n = 0, sa = 0, sb = 0;
      for (Eigen::Index i : rows) {
        const double u = x[a][i], v = x[b][i];
        if (!std::isfinite(u) || !std::isfinite(v)) continue;
        n += 1, sa += u, sb += v;
      }
      if (n < 3) continue;
      const double ma = sa / n, mb = sb / n;
      double saa = 0, sbb = 0, sab = 0;
      for (Eigen::Index i : rows) {
        const double u = x[a][i], v = x[b][i];
        if (!std::isfinite(u) || !std::isfinite(v)) continue;
        saa += (u - ma) * (u - ma), sbb += (v - mb) * (v - mb), sab += (u - ma) * (v - mb);
      }
      if (!(saa > 0 && sbb > 0)) continue;
      const double r = sab / std::sqrt(saa * sbb);
      if (std::abs(r) < min_abs_r) continue;
      out[a].emplace_back(channels[b], r);
      out[b].emplace_back(channels[a], r);
    }
  }
  for (auto& list : out)
    std::stable_sort(list.begin(), list.end(), [](const auto& p, const auto& q) {
      return std::abs(p.second) > std::abs(q.second);
    });
  return out;
}

namespace {

// Each item's share of the positive importances, and the items ranked by importance.
template <typename Items>
void rank_by_share(Items* items) {
  double positive = 0;
  for (const auto& i : *items) positive += std::max(0.0, i.importance_nT2);
  for (auto& i : *items) i.share = positive > 0 ? std::max(0.0, i.importance_nT2) / positive : 0;
  std::stable_sort(items->begin(), items->end(), [](const auto& x, const auto& y) {
    return x.importance_nT2 > y.importance_nT2;
  });
}

}  // namespace

const ChannelImportance* Attribution::first_aircraft_channel() const {
  for (const ChannelImportance& c : channels)
    if (!c.trajectory) return &c;
  return nullptr;
}

Attribution permutation_importance(const Model& model, const FlightData& data,
                                   std::shared_ptr<NeuralNetwork> network, int repeats,
                                   unsigned seed) {
  if (!model.neural || !model.neural->trained())
    throw Error("attribution: the model has no trained neural stage (run magcomp train)");
  if (repeats < 1) throw Error("attribution: repeats must be >= 1");
  const NeuralSpec& s = *model.neural;
  const NeuralInputs in = neural_inputs(model, data);
  const Eigen::VectorXd target = neural_target(model, data, in);
  const Eigen::Index n = data.size(), f = in.features.cols();
  if (!network) network = load_neural_network(model, static_cast<int>(f));
  const Eigen::MatrixXd z = standardised_inputs(s, in.features);
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < n; ++i)
    if (std::isfinite(target[i])) rows.push_back(i);
  if (rows.size() < 2)
    throw Error(data.source() + ": attribution: no sample with a finite target to score");
  const Eigen::VectorXd line =
      data.has("line") ? Eigen::VectorXd(data.column("line")) : Eigen::VectorXd::Zero(n);
  std::map<double, std::vector<size_t>> by_line;  // scored rows of each line (indices in rows)
  for (size_t r = 0; r < rows.size(); ++r) by_line[line[rows[r]]].push_back(r);

  Attribution a;
  a.samples = static_cast<Eigen::Index>(rows.size());
  a.repeats = repeats;
  const Eigen::VectorXd base =
      squared_errors(network_output_nT(s, z, *network, &in.tl_columns), target, rows);
  a.baseline_mse_nT2 = base.mean();
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ULL + 11);
  std::vector<size_t> order(rows.size());
  // The mean rise of the squared error over the scored rows when the inputs `group` are
  // shuffled together (one permutation per repeat), per scored row.
  const auto rise_of = [&](const std::vector<Eigen::Index>& group) {
    Eigen::VectorXd rise = Eigen::VectorXd::Zero(a.samples);
    for (int rep = 0; rep < repeats; ++rep) {
      std::iota(order.begin(), order.end(), size_t{0});
      std::shuffle(order.begin(), order.end(), rng);
      Eigen::MatrixXd zs = z;
      for (Eigen::Index k : group)
        for (size_t r = 0; r < rows.size(); ++r) zs(k, rows[r]) = z(k, rows[order[r]]);
      rise +=
          squared_errors(network_output_nT(s, zs, *network, &in.tl_columns), target, rows) - base;
    }
    return Eigen::VectorXd(rise / repeats);
  };
  for (Eigen::Index k = 0; k < f; ++k) {
    InputImportance imp;
    imp.feature = k < static_cast<Eigen::Index>(s.features.size())
                      ? s.features[static_cast<size_t>(k)]
                      : "input " + std::to_string(k);
    const Eigen::VectorXd rise = rise_of({k});
    imp.importance_nT2 = rise.mean();
    for (const auto& [l, members] : by_line) {
      double sum = 0;
      for (size_t r : members) sum += rise[static_cast<Eigen::Index>(r)];
      imp.per_line_nT2.emplace_back(l, sum / static_cast<double>(members.size()));
    }
    a.inputs.push_back(std::move(imp));
  }
  // The recorded channels: every input reading one is shuffled with it. A channel read by one
  // input alone has that input's figure. The inputs that read no channel are the model's own.
  std::vector<std::string> channel_order;
  std::vector<std::vector<Eigen::Index>> readers;  // the inputs of each channel
  std::vector<bool> reads_a_channel(static_cast<size_t>(f), false);
  for (const auto& [channel, inputs] : channel_input_groups(model)) {
    std::vector<Eigen::Index> group;
    for (std::int64_t k : inputs) {
      if (k >= f) continue;
      group.push_back(static_cast<Eigen::Index>(k));
      reads_a_channel[static_cast<size_t>(k)] = true;
    }
    if (group.empty()) continue;
    channel_order.push_back(channel);
    readers.push_back(std::move(group));
  }
  std::vector<Eigen::Index> own;
  for (Eigen::Index k = 0; k < f; ++k)
    if (!reads_a_channel[static_cast<size_t>(k)]) own.push_back(k);
  const auto alikes = look_alike_channels(data, channel_order, rows);
  for (size_t j = 0; j < channel_order.size(); ++j) {
    ChannelImportance ci;
    ci.channel = channel_order[j];
    const std::vector<Eigen::Index>& group = readers[j];
    for (Eigen::Index k : group) ci.features.push_back(a.inputs[static_cast<size_t>(k)].feature);
    ci.importance_nT2 = group.size() == 1 ? a.inputs[static_cast<size_t>(group[0])].importance_nT2
                                          : rise_of(group).mean();
    ci.look_alikes = alikes[j];
    ci.trajectory = is_position_channel(ci.channel) || is_earth_frame_velocity(ci.channel);
    a.channels.push_back(std::move(ci));
  }
  if (!own.empty()) a.own_inputs_nT2 = rise_of(own).mean();
  rank_by_share(&a.inputs);
  rank_by_share(&a.channels);
  return a;
}

Attribution average_attributions(const std::vector<Attribution>& each) {
  if (each.empty()) throw Error("attribution: no attribution to average");
  Attribution a = each.front();
  if (each.size() == 1) return a;
  const auto index = [](const auto& items, const auto& name_of) {
    std::map<std::string, size_t> at;
    for (size_t k = 0; k < items.size(); ++k) at[name_of(items[k])] = k;
    return at;
  };
  const auto feature = [](const InputImportance& i) { return i.feature; };
  const auto channel = [](const ChannelImportance& c) { return c.channel; };
  const double count = static_cast<double>(each.size());
  a.baseline_mse_nT2 = 0;
  a.own_inputs_nT2 = 0;
  for (auto& i : a.inputs) {
    i.importance_nT2 = 0;
    for (auto& l : i.per_line_nT2) l.second = 0;
  }
  for (auto& c : a.channels) c.importance_nT2 = 0;
  const auto inputs_at = index(a.inputs, feature);
  const auto channels_at = index(a.channels, channel);
  for (const Attribution& b : each) {
    if (b.inputs.size() != a.inputs.size() || b.channels.size() != a.channels.size())
      throw Error("attribution: the networks to average do not read the same inputs");
    a.baseline_mse_nT2 += b.baseline_mse_nT2 / count;
    a.own_inputs_nT2 += b.own_inputs_nT2 / count;
    for (const InputImportance& i : b.inputs) {
      const auto at = inputs_at.find(i.feature);
      if (at == inputs_at.end() ||
          a.inputs[at->second].per_line_nT2.size() != i.per_line_nT2.size())
        throw Error("attribution: the networks to average do not read the same inputs ('" +
                    i.feature + "')");
      InputImportance& to = a.inputs[at->second];
      to.importance_nT2 += i.importance_nT2 / count;
      for (size_t l = 0; l < i.per_line_nT2.size(); ++l)
        to.per_line_nT2[l].second += i.per_line_nT2[l].second / count;
    }
    for (const ChannelImportance& c : b.channels) {
      const auto at = channels_at.find(c.channel);
      if (at == channels_at.end())
        throw Error("attribution: the networks to average do not read the same channels ('" +
                    c.channel + "')");
      a.channels[at->second].importance_nT2 += c.importance_nT2 / count;
    }
  }
  a.networks = static_cast<int>(each.size());
  rank_by_share(&a.inputs);
  rank_by_share(&a.channels);
  return a;
}

}  // namespace magcomp
