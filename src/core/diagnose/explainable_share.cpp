// magcomp: the explainable share of a held-out residual (cross-fitted flexible model + null).
#include "magcomp/core/diagnose/explainable_share.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <future>
#include <map>

#include "magcomp/core/math/tall_products.h"
#include "magcomp/core/model/signal.h"

namespace magcomp {
namespace {

constexpr int kFunctions = 9;    // per channel: z, 4 hinges, lp 10 s, lp 100 s, rate, |rate|
constexpr int kProjections = 4;  // B̂x, B̂y, B̂z, 1
constexpr int kTopChannels = 6;  // channels in the combined model
constexpr int kStride = 2;       // every kStride-th held-out sample is used to fit
constexpr double kRidge = 1e-2;  // ridge per row, on standardised columns

// The nine functions of one channel over the whole flight (N x 9), standardised; kept in single
// precision (a share estimate needs no more, and a 5 h flight's ~100 channels then hold ~0.65 GB
// instead of 1.3 GB).
using Functions = Eigen::MatrixXf;
Functions channel_functions(const Eigen::Ref<const Eigen::VectorXd>& x,
                            const Eigen::Ref<const Eigen::VectorXd>& t) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd z = x;
  double mean = 0, ss = 0, cnt = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (std::isfinite(x[i])) {
      mean += x[i];
      cnt += 1;
    }
  }
  mean /= std::max(cnt, 1.0);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (std::isfinite(x[i])) ss += (x[i] - mean) * (x[i] - mean);
  }
  const double sd = std::sqrt(ss / std::max(cnt - 1, 1.0));
  for (Eigen::Index i = 0; i < n; ++i) z[i] = std::isfinite(x[i]) ? (x[i] - mean) / sd : 0.0;
  std::vector<double> sorted(z.data(), z.data() + n);
  std::sort(sorted.begin(), sorted.end());
  Eigen::MatrixXd f(n, kFunctions);
  f.col(0) = z;
  for (int q = 0; q < 4; ++q) {
    const double knot = sorted[static_cast<size_t>((q + 1) * (n - 1) / 5)];
    f.col(1 + q) = (z.array() - knot).max(0.0).matrix();
  }
  f.col(5) = apply_transforms({{TransformKind::LowPass, 10.0, false}}, t, z);
  f.col(6) = apply_transforms({{TransformKind::LowPass, 100.0, false}}, t, z);
  f.col(7) = apply_transforms({{TransformKind::Derivative, 0.0, false}}, t, z);
  f.col(8) = f.col(7).cwiseAbs();
  for (int c = 0; c < kFunctions; ++c) {  // standardise each function
    const double m = f.col(c).mean();
    const double s = std::sqrt((f.col(c).array() - m).square().mean());
    f.col(c) = s > 1e-12 ? Eigen::VectorXd((f.col(c).array() - m) / s) : Eigen::VectorXd::Zero(n);
  }
  return f.cast<float>();
}

constexpr int kFolds = 4;

struct Problem {
  const Eigen::VectorXd* residual;
  const Eigen::MatrixX3d* direction;
  std::vector<Eigen::Index> rows[kFolds];      // rows of each fold (subsampled)
  std::vector<Eigen::Index> all_rows[kFolds];  // every held-out row of each fold
  std::vector<int> unit;                       // per row: its unit (-1: not held out)
  int units = 0;
  Eigen::Index n = 0;
};

// The design rows of some channels' functions (shifted circularly by `shift`) at `rows`.
Eigen::MatrixXd design(const Problem& p, const std::vector<const Functions*>& functions,
                       const std::vector<Eigen::Index>& rows, Eigen::Index shift) {
  const Eigen::Index cols = static_cast<Eigen::Index>(functions.size()) * kFunctions * kProjections;
  Eigen::MatrixXd a(static_cast<Eigen::Index>(rows.size()), cols);
  for (size_t r = 0; r < rows.size(); ++r) {
    const Eigen::Index i = rows[r];
    const Eigen::Index j = (i + shift) % p.n;
    Eigen::Index c = 0;
    for (const Functions* f : functions) {
      for (int k = 0; k < kFunctions; ++k) {
        const double v = (*f)(j, k);
        const auto ri = static_cast<Eigen::Index>(r);
        a(ri, c++) = v * (*p.direction)(i, 0);
        a(ri, c++) = v * (*p.direction)(i, 1);
        a(ri, c++) = v * (*p.direction)(i, 2);
        a(ri, c++) = v;
      }
    }
  }
  return a;
}

Eigen::VectorXd values_at(const Eigen::VectorXd& x, const std::vector<Eigen::Index>& rows) {
  Eigen::VectorXd v(static_cast<Eigen::Index>(rows.size()));
  for (size_t r = 0; r < rows.size(); ++r) v[static_cast<Eigen::Index>(r)] = x[rows[r]];
  return v;
}

// Cross-fitted share: each fold predicted by a ridge fit on the other folds. With
// `prediction`, the prediction at every held-out row is written there; with `unit_sse` and
// `unit_sst`, the sums per unit (for the bootstrap).
double cross_fit(const Problem& p, const std::vector<const Functions*>& functions,
                 Eigen::Index shift, Eigen::VectorXd* prediction = nullptr,
                 std::vector<double>* unit_sse = nullptr, std::vector<double>* unit_sst = nullptr) {
  double sse = 0, sst = 0;
  std::vector<Eigen::MatrixXd> a(kFolds);
  std::vector<Eigen::VectorXd> y(kFolds);
  const Eigen::Index cols = static_cast<Eigen::Index>(functions.size()) * kFunctions * kProjections;
  Eigen::MatrixXd g_all = Eigen::MatrixXd::Zero(cols, cols);
  Eigen::VectorXd b_all = Eigen::VectorXd::Zero(cols);
  std::vector<Eigen::MatrixXd> g(kFolds);
  std::vector<Eigen::VectorXd> b(kFolds);
  Eigen::Index rows_all = 0;
  for (int f = 0; f < kFolds; ++f) {
    a[f] = design(p, functions, p.rows[f], shift);
    y[f] = values_at(*p.residual, p.rows[f]);
    g[f] = gram(a[f]);
    b[f] = a[f].transpose() * y[f];
    g_all += g[f];
    b_all += b[f];
    rows_all += a[f].rows();
  }
  if (unit_sse) unit_sse->assign(static_cast<size_t>(p.units), 0.0);
  if (unit_sst) unit_sst->assign(static_cast<size_t>(p.units), 0.0);
  for (int f = 0; f < kFolds; ++f) {
    if (p.rows[f].empty()) continue;
    Eigen::MatrixXd gt = g_all - g[f];
    gt.diagonal().array() += kRidge * static_cast<double>(rows_all - a[f].rows()) + 1e-9;
    const Eigen::VectorXd coef = gt.ldlt().solve(b_all - b[f]);
    const auto& test_rows = prediction ? p.all_rows[f] : p.rows[f];
    const Eigen::MatrixXd bt = prediction ? design(p, functions, test_rows, shift) : a[f];
    const Eigen::VectorXd yt = prediction ? values_at(*p.residual, test_rows) : y[f];
    const Eigen::VectorXd pred = bt * coef;
    sse += (yt - pred).squaredNorm();
    sst += yt.squaredNorm();
    for (size_t r = 0; r < test_rows.size(); ++r) {
      const auto ri = static_cast<Eigen::Index>(r);
      if (prediction) (*prediction)[test_rows[r]] = pred[ri];
      const auto u = static_cast<size_t>(p.unit[static_cast<size_t>(test_rows[r])]);
      if (unit_sse) (*unit_sse)[u] += (yt[ri] - pred[ri]) * (yt[ri] - pred[ri]);
      if (unit_sst) (*unit_sst)[u] += yt[ri] * yt[ri];
    }
  }
  return sst > 0 ? 1.0 - sse / sst : 0.0;
}

struct Ranked {
  std::vector<std::pair<double, size_t>> by_share;  // share alone, channel index
  double combined = 0.0;
  std::vector<double> unit_sse, unit_sst;  // of the combined model, per unit
};

// The real fit (shift 0) and four nulls with the channels shifted by a fifth of the flight each.
constexpr int kShifts = 5;
Eigen::Index shift_of(const Problem& p, int s) { return (p.n * s) / 5; }

using Channels = std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>>;

// Each channel's share alone at each shift, the channel's functions computed once and let go
// (a 5 h flight's hundred channels would hold ~0.7 GB of them at once): per channel, kShifts
// shares. The channels are split between two workers.
std::vector<std::array<double, kShifts>> shares_alone(
    const Problem& p, const Channels& channels, const Eigen::Ref<const Eigen::VectorXd>& t_s) {
  std::vector<std::array<double, kShifts>> alone(channels.size());
  const auto work = [&](size_t first) {
    for (size_t k = first; k < channels.size(); k += 2) {
      const Functions f = channel_functions(channels[k].second, t_s);
      for (int s = 0; s < kShifts; ++s)
        alone[k][static_cast<size_t>(s)] = cross_fit(p, {&f}, shift_of(p, s));
    }
  };
  auto other = std::async(std::launch::async, work, size_t{1});
  work(0);
  other.get();
  return alone;
}

// At shift `s`: the channels ranked by their share alone, and the combined model of the first
// kTopChannels that explain something (their functions computed again here).
Ranked rank_and_combine(const Problem& p, const Channels& channels,
                        const Eigen::Ref<const Eigen::VectorXd>& t_s,
                        const std::vector<std::array<double, kShifts>>& alone, int s,
                        Eigen::VectorXd* prediction) {
  Ranked r;
  for (size_t k = 0; k < channels.size(); ++k)
    r.by_share.emplace_back(alone[k][static_cast<size_t>(s)], k);
  std::sort(r.by_share.begin(), r.by_share.end(),
            [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<Functions> top_functions;
  for (const auto& [share, k] : r.by_share) {
    if (share > 0 && static_cast<int>(top_functions.size()) < kTopChannels)
      top_functions.push_back(channel_functions(channels[k].second, t_s));
  }
  if (top_functions.empty()) return r;
  std::vector<const Functions*> top;
  for (const Functions& f : top_functions) top.push_back(&f);
  r.combined =
      std::max(0.0, cross_fit(p, top, shift_of(p, s), prediction, &r.unit_sse, &r.unit_sst));
  return r;
}

}  // namespace

namespace {

// The held-out rows of each fold (every kStride-th of them for the fit), the units renumbered;
// rows with a NaN residual or direction are left out.
Problem make_problem(const Eigen::VectorXd& residual, const std::vector<int>& unit,
                     const Eigen::MatrixX3d& direction) {
  Problem p;
  p.residual = &residual;
  p.direction = &direction;
  p.n = residual.size();
  p.unit = unit;
  Eigen::Index counter[kFolds] = {0};
  for (Eigen::Index i = 0; i < p.n; ++i) {
    const int u = unit[static_cast<size_t>(i)];
    if (u < 0 || !std::isfinite(residual[i]) || !direction.row(i).allFinite()) {
      p.unit[static_cast<size_t>(i)] = -1;
      continue;
    }
    p.units = std::max(p.units, u + 1);
    const int f = u % kFolds;
    p.all_rows[f].push_back(i);
    if (counter[f]++ % kStride == 0) p.rows[f].push_back(i);
  }
  return p;
}

// The share's own spread: a bootstrap (200 draws, fixed seed) over the held-out units.
double bootstrap_sd(const Ranked& r, int units) {
  if (r.unit_sse.empty()) return 0;
  std::vector<double> boot;
  unsigned state = 12345u;
  for (int b = 0; b < 200; ++b) {
    double e = 0, t = 0;
    for (int k = 0; k < units; ++k) {
      state = state * 1664525u + 1013904223u;
      const auto u = static_cast<size_t>(state % static_cast<unsigned>(units));
      e += r.unit_sse[u];
      t += r.unit_sst[u];
    }
    boot.push_back(t > 0 ? std::max(0.0, 1.0 - e / t) : 0.0);
  }
  double m = 0, v = 0;
  for (double x : boot) m += x / boot.size();
  for (double x : boot) v += (x - m) * (x - m) / (boot.size() - 1);
  return std::sqrt(v);
}

// Where the predicted part sits: by time scale (low-passes along the held-out samples in time
// order) and by line.
void locate_prediction(const Eigen::VectorXd& prediction,
                       const Eigen::Ref<const Eigen::VectorXd>& t_s, const Eigen::VectorXd& line,
                       ExplainableShare* out) {
  const Eigen::Index n = prediction.size();
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (std::isfinite(prediction[i])) rows.push_back(i);
  }
  if (rows.size() > 10 && out->share > 0) {
    Eigen::VectorXd t(static_cast<Eigen::Index>(rows.size())), x(t.size());
    for (size_t k = 0; k < rows.size(); ++k) {
      t[static_cast<Eigen::Index>(k)] = t_s[rows[k]];
      x[static_cast<Eigen::Index>(k)] = prediction[rows[k]];
    }
    const Eigen::VectorXd slow = apply_transforms({{TransformKind::LowPass, 100.0, false}}, t, x);
    const Eigen::VectorXd mid =
        apply_transforms({{TransformKind::LowPass, 10.0, false}}, t, x) - slow;
    const Eigen::VectorXd fast = x - slow - mid;
    const double total = slow.squaredNorm() + mid.squaredNorm() + fast.squaredNorm();
    if (total > 0) {
      out->time_scales = {{"slower than 100 s", slow.squaredNorm() / total},
                          {"10-100 s", mid.squaredNorm() / total},
                          {"faster than 10 s", fast.squaredNorm() / total}};
    }
    std::map<double, double> by_line;
    double all = 0;
    for (size_t k = 0; k < rows.size(); ++k) {
      const double v = x[static_cast<Eigen::Index>(k)] * x[static_cast<Eigen::Index>(k)];
      by_line[line[rows[k]]] += v;
      all += v;
    }
    for (const auto& [l, v] : by_line) out->lines.emplace_back(l, all > 0 ? v / all : 0.0);
    std::sort(out->lines.begin(), out->lines.end(),
              [](const auto& a, const auto& b) { return a.second > b.second; });
  }
}

}  // namespace

ExplainableShare explainable_share(
    const Eigen::VectorXd& residual, const std::vector<int>& unit, const Eigen::VectorXd& line,
    const Eigen::Ref<const Eigen::VectorXd>& t_s, const Eigen::MatrixX3d& direction,
    const std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>>& channels,
    const std::function<void()>& channels_read) {
  ExplainableShare out;
  const Problem p = make_problem(residual, unit, direction);
  int filled = 0;
  for (const auto& r : p.rows) filled += r.size() >= 20;
  if (filled < 2 || channels.empty()) return out;
  const std::vector<std::array<double, kShifts>> alone = shares_alone(p, channels, t_s);
  if (channels_read) channels_read();
  // The real fit and the four nulls, in parallel (each is independent).
  Eigen::VectorXd prediction = Eigen::VectorXd::Constant(p.n, NAN);
  auto real = std::async(std::launch::async,
                         [&] { return rank_and_combine(p, channels, t_s, alone, 0, &prediction); });
  std::vector<double> null;
  for (int s = 1; s < kShifts; ++s)
    null.push_back(rank_and_combine(p, channels, t_s, alone, s, nullptr).combined);
  const Ranked r = real.get();
  double mean = 0, var = 0, mx = 0;
  for (double v : null) {
    mean += v / null.size();
    mx = std::max(mx, v);
  }
  for (double v : null) var += (v - mean) * (v - mean) / (null.size() - 1);
  const double sd = std::sqrt(var);
  out.computed = true;
  out.share = r.combined;
  out.noise_floor = std::max({mean + 2 * sd, mx, 0.01});
  const double boot_sd = bootstrap_sd(r, p.units);
  out.uncertainty = std::sqrt(sd * sd + boot_sd * boot_sd);
  out.within_noise = out.share <= out.noise_floor;
  for (const auto& [share, k] : r.by_share) {
    if (out.channels.size() >= 8) break;
    out.channels.emplace_back(channels[k].first, share);
  }
  locate_prediction(prediction, t_s, line, &out);
  return out;
}

}  // namespace magcomp
