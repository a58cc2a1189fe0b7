// magcomp: the training loop (libtorch): Adam with weight decay, learning rate decayed per epoch,
// MSE on standardised targets, shuffled windows, early stopping on validation flights.
#include "magcomp/neural/trainer.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <random>

#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "networks.h"

namespace magcomp {
namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

struct Tensors {
  torch::Tensor x, target, tl, first;
  std::vector<torch::Tensor> groups;     // the inputs of each recorded channel (channel_sparsity)
  std::vector<std::string> group_names;  // the channel of each group
};

Tensors tensors_of(const TrainingData& d) {
  Tensors t;
  const int64_t n = d.features.rows(), f = d.features.cols();
  t.x = torch::from_blob(const_cast<float*>(d.features.data()), {n, f}, torch::kFloat32);
  t.target = torch::from_blob(const_cast<float*>(d.target.data()), {n}, torch::kFloat32);
  if (d.tl_columns.size() > 0) {
    t.tl = torch::from_blob(const_cast<float*>(d.tl_columns.data()), {n, d.tl_columns.cols()},
                            torch::kFloat32);
  }
  t.first = torch::from_blob(const_cast<int64_t*>(d.first_row.data()), {n}, torch::kInt64);
  for (size_t c = 0; c < d.channel_groups.size(); ++c) {
    if (d.channel_groups[c].empty()) continue;
    t.groups.push_back(torch::tensor(d.channel_groups[c], torch::kInt64));
    t.group_names.push_back(c < d.channel_names.size() ? d.channel_names[c] : "");
  }
  return t;
}

/// The windows ending at `ends` (a [B] int64 tensor): [B, k, F], padded at each flight's start.
torch::Tensor gather_windows(const Tensors& t, const torch::Tensor& ends, int64_t k) {
  const torch::Tensor offsets = torch::arange(-(k - 1), 1, torch::kInt64);  // [k]
  torch::Tensor rows = ends.unsqueeze(1) + offsets.unsqueeze(0);            // [B, k]
  rows = torch::max(rows, t.first.index_select(0, ends).unsqueeze(1));
  return t.x.index_select(0, rows.flatten()).view({ends.size(0), k, t.x.size(1)});
}

double evaluate_rmse(CompensatorNet& net, const Tensors& t, const std::vector<int64_t>& ends,
                     int64_t k) {
  if (ends.empty()) return NAN;
  torch::NoGradGuard g;
  net->eval();
  double sum = 0.0;
  const int64_t chunk = 4096, n = static_cast<int64_t>(ends.size());
  for (int64_t s = 0; s < n; s += chunk) {
    const int64_t c = std::min(chunk, n - s);
    const torch::Tensor e =
        torch::from_blob(const_cast<int64_t*>(ends.data() + s), {c}, torch::kInt64);
    const torch::Tensor tl = t.tl.defined() ? t.tl.index_select(0, e) : torch::Tensor();
    const torch::Tensor err =
        net->forward(gather_windows(t, e, k), tl) - t.target.index_select(0, e);
    sum += err.pow(2).sum().item<double>();
  }
  net->train();
  return std::sqrt(sum / static_cast<double>(n));
}

std::string clock_text(double s) {
  char buf[32];
  const int v = static_cast<int>(std::lround(std::max(0.0, s)));
  std::snprintf(buf, sizeof(buf), "%d:%02d", v / 60, v % 60);
  return buf;
}

/// One pass over the shuffled windows; returns the mean training MSE (standardised).
/// ||W_c||: the norm of the first-layer weights `w` [R, F] on one channel's input columns `g`
/// (the 1e-12 keeps its gradient finite at zero). What the group lasso weighs and the cut ranks.
torch::Tensor group_norm(const torch::Tensor& w, const torch::Tensor& g) {
  return (w.index_select(1, g).pow(2).sum() + 1e-12).sqrt();
}

/// `sparsity`: the group lasso's weight (0: none); `cut`: input columns held at zero after
/// every step (undefined: none).
double run_epoch(CompensatorNet& net, torch::optim::Adam& opt, const Tensors& t,
                 std::vector<int64_t>& ends, const NeuralSpec& spec, double sparsity,
                 const torch::Tensor& cut, std::mt19937_64& rng,
                 const std::function<void(double, double)>& on_progress) {
  std::shuffle(ends.begin(), ends.end(), rng);
  const int64_t n = static_cast<int64_t>(ends.size()), b = spec.training.batch;
  double sum = 0.0;
  int64_t seen = 0;
  for (int64_t s = 0; s < n; s += b) {
    const int64_t c = std::min(b, n - s);
    const torch::Tensor e = torch::from_blob(ends.data() + s, {c}, torch::kInt64);
    const torch::Tensor tl = t.tl.defined() ? t.tl.index_select(0, e) : torch::Tensor();
    const torch::Tensor pred = net->forward(gather_windows(t, e, spec.window), tl);
    const torch::Tensor loss = torch::mse_loss(pred, t.target.index_select(0, e));
    opt.zero_grad();
    if (sparsity > 0 && !t.groups.empty()) {
      // The group lasso on the channels: sqrt(n_c) ||W_c|| for each channel's inputs.
      const torch::Tensor w = net->input_weights();
      torch::Tensor penalty = torch::zeros({}, w.options());
      for (const torch::Tensor& g : t.groups)
        penalty = penalty + std::sqrt(static_cast<double>(g.size(0))) * group_norm(w, g);
      (loss + sparsity * penalty).backward();
    } else {
      loss.backward();
    }
    opt.step();
    if (cut.defined()) net->zero_inputs(cut);
    sum += loss.item<double>() * static_cast<double>(c);
    seen += c;
    if (on_progress) on_progress(static_cast<double>(seen) / static_cast<double>(n), sum / seen);
  }
  return sum / static_cast<double>(std::max<int64_t>(seen, 1));
}

}  // namespace

TrainResult train_network(const NeuralSpec& spec, const TrainingData& train,
                          const TrainingData& validation, const std::string& weights_path,
                          bool progress) {
  if (train.ends.empty()) throw Error("train: no training windows (no finite target)");
  torch::manual_seed(spec.training.seed);
  torch::set_num_threads(spec.training.threads);
  const int64_t k = spec.window;
  const int n_tl = static_cast<int>(train.tl_columns.cols());
  CompensatorNet net(spec, static_cast<int>(train.features.cols()), n_tl);
  net->train();
  const Tensors tt = tensors_of(train);
  const bool has_val = !validation.ends.empty();
  const Tensors tv = has_val ? tensors_of(validation) : Tensors{};
  std::mt19937_64 rng(spec.training.seed);
  std::vector<int64_t> ends = train.ends;
  TrainResult r;
  double best = INFINITY;
  std::vector<torch::Tensor> best_state;
  const bool tty = ::isatty(2);
  const auto t0 = Clock::now();
  const int epochs = spec.training.epochs;
  const auto keep_best = [&]() {
    best_state.clear();
    for (const auto& p : net->parameters()) best_state.push_back(p.detach().clone());
  };
  const auto restore_best = [&]() {
    torch::NoGradGuard g;
    auto params = net->parameters();
    for (size_t i = 0; i < params.size(); ++i) params[i].copy_(best_state[i]);
  };
  // One training phase: up to `epochs` epochs from a fresh Adam at learning rate `lr`,
  // early-stopped on validation; the best weights so far (both phases) kept in best_state.
  const auto phase = [&](double sparsity, const torch::Tensor& cut, const char* label, double lr) {
    torch::optim::Adam opt(net->parameters(),
                           torch::optim::AdamOptions(lr).weight_decay(spec.training.weight_decay));
    int since_best = 0;
    const int first = r.epochs_run + 1, last = r.epochs_run + epochs;
    for (int epoch = first; epoch <= last; ++epoch) {
      auto last_draw = Clock::now();
      const auto on_progress = [&](double frac, double mse) {
        if (!progress || !tty || since(last_draw) < 0.25) return;
        last_draw = Clock::now();
        const double done = (epoch - first + frac) / epochs;
        const int bar = static_cast<int>(frac * 24);
        std::fprintf(stderr, "\r%sepoch %d/%d [%s%s] %3.0f%% loss %.4f ETA %s   ", label,
                     epoch - first + 1, epochs, std::string(static_cast<size_t>(bar), '#').c_str(),
                     std::string(static_cast<size_t>(24 - bar), '.').c_str(), frac * 100, mse,
                     clock_text(since(t0) / done * (1 - done)).c_str());
      };
      const double mse = run_epoch(net, opt, tt, ends, spec, sparsity, cut, rng, on_progress);
      r.train_rmse_nT.push_back(std::sqrt(mse) * spec.target_std);
      double val = NAN;
      if (has_val) {
        val = evaluate_rmse(net, tv, validation.ends, k) * spec.target_std;
        r.validation_rmse_nT.push_back(val);
      }
      r.epochs_run = epoch;
      const double score = has_val ? val : mse;
      if (score < best) {
        best = score;
        r.best_epoch = epoch;
        since_best = 0;
        keep_best();
      } else {
        ++since_best;
      }
      if (progress) {
        const double done = static_cast<double>(epoch - first + 1) / epochs;
        std::fprintf(stderr, "%s%sepoch %d/%d  train rmse %.3f nT", tty ? "\r" : "", label,
                     epoch - first + 1, epochs, r.train_rmse_nT.back());
        if (has_val) std::fprintf(stderr, "  validation rmse %.3f nT", val);
        std::fprintf(stderr, "  lr %.2e  %s elapsed, ETA %s%s\n", lr, clock_text(since(t0)).c_str(),
                     clock_text(since(t0) / done * (1 - done)).c_str(),
                     since_best == 0 ? "  *" : "");
      }
      if (has_val && since_best >= spec.training.patience) {
        if (progress)
          std::fprintf(stderr, "early stop: no better validation for %d epochs\n", since_best);
        break;
      }
      lr *= spec.training.lr_decay;
      for (auto& group : opt.param_groups()) {
        static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
      }
    }
  };
  const double sparsity = spec.training.channel_sparsity;
  phase(sparsity, torch::Tensor(), "", spec.training.learning_rate);
  if (best_state.empty())
    throw Error("train: no epoch gave a finite loss (neural.training.learning_rate " +
                std::to_string(spec.training.learning_rate) + " too large, or inputs too large)");
  restore_best();
  if (sparsity > 0 && spec.training.channel_cut > 0 && !tt.groups.empty()) {
    // The relaxed lasso: cut the channels the penalty shrank, refit the rest without it.
    std::vector<std::pair<double, size_t>> norms;
    {
      torch::NoGradGuard g;
      const torch::Tensor w = net->input_weights();
      for (size_t c = 0; c < tt.groups.size(); ++c)
        norms.emplace_back(group_norm(w, tt.groups[c]).item<double>(), c);
    }
    std::sort(norms.rbegin(), norms.rend());
    const double floor = spec.training.channel_cut * norms.front().first;
    if (progress) {
      std::fprintf(stderr, "channel weight norms (of the largest):");
      for (const auto& [norm, c] : norms)
        std::fprintf(stderr, " %s %.3g", tt.group_names[c].c_str(), norm / norms.front().first);
      std::fprintf(stderr, "\n");
    }
    std::vector<int64_t> cut_columns;
    for (const auto& [norm, c] : norms) {
      const std::string& name = tt.group_names[c];
      if (norm >= floor) {
        r.kept_channels.push_back(name);
        continue;
      }
      ++r.cut_channels;
      const torch::Tensor& g = tt.groups[c];
      cut_columns.insert(cut_columns.end(), g.data_ptr<int64_t>(),
                         g.data_ptr<int64_t>() + g.size(0));
    }
    if (!cut_columns.empty()) {
      const torch::Tensor cut = torch::tensor(cut_columns, torch::kInt64);
      net->zero_inputs(cut);
      // The cut network's own score is the one to beat: the weights kept read no cut channel.
      best = has_val ? evaluate_rmse(net, tv, validation.ends, k) * spec.target_std : INFINITY;
      keep_best();
      r.refit_from_epoch = r.epochs_run + 1;
      if (progress)
        std::fprintf(stderr, "channel_cut: %zu of %zu channels kept; refit without the penalty\n",
                     r.kept_channels.size(), norms.size());
      phase(0.0, cut, "refit ",
            spec.training.learning_rate * std::pow(spec.training.lr_decay, r.best_epoch));
      restore_best();
    }
  }
  if (has_val) r.best_validation_rmse_nT = best;
  r.seconds = since(t0);
  if (n_tl > 0 && net->tl_linear) {
    const torch::Tensor w = net->tl_linear->weight.detach().to(torch::kFloat64).contiguous();
    r.tl_weights = Eigen::Map<const Eigen::VectorXd>(w.data_ptr<double>(), n_tl);
  }
  check_output_path(weights_path);
  const std::string tmp = temporary_path(weights_path);
  try {
    torch::save(net, tmp);
  } catch (const std::exception& e) {
    std::remove(tmp.c_str());
    throw Error(weights_path + ": cannot write the weights (" + e.what() + ")");
  }
  commit_temporary(tmp, weights_path);
  return r;
}

double time_one_epoch(const NeuralSpec& spec, const TrainingData& data, bool torch_lstm) {
  torch::manual_seed(spec.training.seed);
  torch::set_num_threads(spec.training.threads);
  CompensatorNet net(spec, static_cast<int>(data.features.cols()),
                     static_cast<int>(data.tl_columns.cols()));
  net->fused_lstm = !torch_lstm;
  net->train();
  torch::optim::Adam opt(net->parameters(), torch::optim::AdamOptions(spec.training.learning_rate)
                                                .weight_decay(spec.training.weight_decay));
  const Tensors t = tensors_of(data);
  std::mt19937_64 rng(spec.training.seed);
  std::vector<int64_t> ends = data.ends;
  const auto t0 = Clock::now();
  run_epoch(net, opt, t, ends, spec, spec.training.channel_sparsity, torch::Tensor(), rng, nullptr);
  return since(t0);
}

}  // namespace magcomp
