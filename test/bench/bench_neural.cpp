// magcomp benchmark: (1) one training epoch of the CNN of Laoué's report (window 80) on N windows
// of simulated flights with libtorch, writing the very same standardised data for the PyTorch
// script (scripts/bench_neural_torch.py); (2) batch-1 streaming inference per sample (MLP, CNN,
// LSTM). Usage: magcomp_bench_neural N_WINDOWS DATA_OUT.bin     (simulate, write the data, time,
// latency)
//        magcomp_bench_neural --epoch DATA.bin [cnn|lstm|lstm-torch [BATCH]]  (time one epoch
//          of that architecture, as its model file sets it, on a written file; lstm-torch: the
//          LSTM through torch::nn::LSTM's own backward)
#include <torch/torch.h>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>

#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/neural/dataset.h"
#include "magcomp/core/sim/simulator.h"
#include "magcomp/core/stream/streaming_compensator.h"
#include "magcomp/neural/trainer.h"

using namespace magcomp;

namespace {

FlightData simulate_flight(unsigned seed) {
  sim::Scenario s =
      sim::load_scenario(std::string(MAGCOMP_SOURCE_DIR) + "/config/scenarios/bench_5h.yaml");
  s.seed = seed;
  s.aircraft_seed = 42;
  FlightData f = sim::simulate(s, Igrf::installed()).flight;
  f.set_source("bench_5h_seed" + std::to_string(seed));
  return f;
}

Model model_of(const std::string& name) {
  Model m =
      load_model_yaml(std::string(MAGCOMP_SOURCE_DIR) + "/config/models/neural/" + name + ".yaml");
  m.fit.lines = {1001.02};  // the bench flights' compensation box
  m.fit.lambda = 1e-4;
  return m;
}

template <typename T>
void put(std::ofstream& o, const T* p, size_t n) {
  o.write(reinterpret_cast<const char*>(p), static_cast<std::streamsize>(n * sizeof(T)));
}

}  // namespace

void print_epoch(const NeuralSpec& s, const TrainingData& d, double epoch_s,
                 const char* variant = "") {
  std::printf(
      "cpp_libtorch %s%s_epoch windows %zu features %ld window %d batch %d threads %d seconds "
      "%.2f\n",
      architecture_name(s.architecture), variant, d.ends.size(),
      static_cast<long>(d.features.cols()), s.window, s.training.batch, s.training.threads,
      epoch_s);
}

/// One epoch of `arch` (cnn or lstm, its layers and batch from its model file, every window) on
/// the data file another run wrote (the same bytes PyTorch reads).
int epoch_from_file(const std::string& path, const std::string& arch, int batch) {
  std::ifstream in(path, std::ios::binary);
  std::int64_t head[5] = {0, 0, 0, 0, 0};
  in.read(reinterpret_cast<char*>(head), sizeof(head));
  if (!in || head[0] <= 0 || head[1] <= 0 || head[2] <= 0 || head[3] <= 0 || head[3] > head[0] ||
      head[0] > (std::int64_t{1} << 32) || head[1] > 4096) {
    std::fprintf(stderr, "%s: not a benchmark data file (missing, short or bad header)\n",
                 path.c_str());
    return 2;
  }
  TrainingData d;
  d.features.resize(head[0], head[1]);
  d.target.resize(head[0]);
  d.first_row.resize(static_cast<size_t>(head[0]));
  d.ends.resize(static_cast<size_t>(head[3]));
  in.read(reinterpret_cast<char*>(d.features.data()), d.features.size() * 4);
  in.read(reinterpret_cast<char*>(d.target.data()), d.target.size() * 4);
  in.read(reinterpret_cast<char*>(d.first_row.data()), head[0] * 8);
  in.read(reinterpret_cast<char*>(d.ends.data()), head[3] * 8);
  if (!in) {
    std::fprintf(stderr, "%s: short or unreadable benchmark data file\n", path.c_str());
    return 2;
  }
  const bool torch_lstm = arch == "lstm-torch";
  NeuralSpec s = *model_of(torch_lstm ? "lstm" : arch).neural;
  s.training.threads = 2;
  if (batch > 0) s.training.batch = batch;
  s.window = static_cast<int>(head[2]);
  s.feature_mean = Eigen::VectorXd::Zero(head[1]);
  const double epoch_s = time_one_epoch(s, d, torch_lstm);
  print_epoch(s, d, epoch_s, torch_lstm ? "-torch" : "");
  return 0;
}

int main(int argc, char** argv) {
  if (argc >= 3 && argc <= 5 && std::string(argv[1]) == "--epoch") {
    const std::string arch = argc >= 4 ? argv[3] : "cnn";
    if (arch != "cnn" && arch != "lstm" && arch != "lstm-torch") {
      std::fprintf(stderr, "--epoch: architecture '%s': cnn, lstm or lstm-torch\n", arch.c_str());
      return 2;
    }
    return epoch_from_file(argv[2], arch, argc == 5 ? std::atoi(argv[4]) : 0);
  }
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s N_WINDOWS DATA_OUT.bin\n", argv[0]);
    return 2;
  }
  const long long want = std::atoll(argv[1]);
  const std::string out = argv[2];
  using Clock = std::chrono::steady_clock;
  std::vector<FlightData> flights;
  long long total = 0;
  for (unsigned seed = 11; total < want; ++seed) {
    flights.push_back(simulate_flight(seed));
    total += flights.back().size();
  }
  Model m = model_of("cnn");
  fit_model(m, {&flights[0]});
  NeuralSpec& s = *m.neural;
  s.training.threads = 2;
  const std::vector<FlightSamples> fs = flight_samples(m, flights);
  fit_normalisation(s, fs);
  TrainingData d = make_training_data(s, fs, Eigen::VectorXd(), 1);
  if (static_cast<long long>(d.ends.size()) > want) d.ends.resize(static_cast<size_t>(want));
  {
    std::ofstream o(out, std::ios::binary);
    const std::int64_t head[5] = {d.features.rows(), d.features.cols(), s.window,
                                  static_cast<std::int64_t>(d.ends.size()), s.training.batch};
    put(o, head, 5);
    put(o, d.features.data(), static_cast<size_t>(d.features.size()));
    put(o, d.target.data(), static_cast<size_t>(d.target.size()));
    put(o, d.first_row.data(), d.first_row.size());
    put(o, d.ends.data(), d.ends.size());
  }
  const double epoch_s = time_one_epoch(s, d);
  print_epoch(s, d, epoch_s);
  std::fflush(stdout);

  // Batch-1 streaming inference: per pushed sample (TL stage + features + network), one thread.
  const FlightData& f = flights.back();
  const Eigen::VectorXd igrf = igrf_total_nT(f, Igrf::installed());
  for (const char* arch : {"mlp", "cnn", "lstm"}) {
    Model a = model_of(arch);
    a.neural->training.epochs = 1;
    a.neural->training.stride = 50;
    const std::string dir = "/tmp/magcomp_bench_neural_" + std::string(arch);
    train_bundle(a, {flights[0]}, {}, dir, false);
    torch::set_num_threads(1);
    StreamingCompensator sc(load_model_yaml(dir));
    std::vector<double> us;
    const Eigen::Index n = std::min<Eigen::Index>(f.size(), 20000);
    for (Eigen::Index i = 0; i < n; ++i) {
      StreamSample x;
      x.t_s = f.tt()[i];
      x.scalar_nT = f.column(a.scalar)[i];
      x.vector_nT = {f.column("flux_c_x")[i], f.column("flux_c_y")[i], f.column("flux_c_z")[i]};
      for (const auto& c : sc.required_channels())
        x.channels.push_back(f.has(c) ? f.column(c)[i] : NAN);
      x.igrf_nT = igrf[i];
      const auto t0 = Clock::now();
      sc.push(x);
      us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    }
    std::sort(us.begin() + 100, us.end());  // the first samples fill the window
    auto pct = [&](double p) { return us[100 + static_cast<size_t>(p * (us.size() - 101))]; };
    std::printf("streaming %s (window %d): per sample us p50 %.1f p99 %.1f max %.1f\n", arch,
                a.neural->window, pct(0.5), pct(0.99), pct(1.0));
  }
  return 0;
}
