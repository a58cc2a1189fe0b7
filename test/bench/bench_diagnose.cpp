// magcomp benchmark: diagnose with the full search on a 1 h simulated flight widened to ~100
// fields (the MIT files' width): extra channels are random walks and on/off loads that explain
// nothing. Prints the flight's size, the number of terms fitted, the wall time and peak memory.
// Usage: magcomp_bench_diagnose SCENARIO.yaml MODEL.yaml [extra_fields] [no-rails]
// (scripts/bench_diagnose; no-rails: DiagnoseOptions::search_rails false)
#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/sim/simulator.h"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s SCENARIO.yaml MODEL.yaml [extra_fields]\n", argv[0]);
    return 2;
  }
  try {
    const magcomp::sim::Simulation sim =
        magcomp::sim::simulate(magcomp::sim::load_scenario(argv[1]), magcomp::Igrf::installed());
    magcomp::FlightData f = sim.flight;
    const int extra = argc > 3 ? std::atoi(argv[3]) : 30;
    std::mt19937_64 rng(7);
    std::normal_distribution<double> normal(0, 1);
    for (int k = 0; k < extra; ++k) {
      Eigen::VectorXd x(f.size());
      double w = 0;
      for (Eigen::Index i = 0; i < f.size(); ++i) {
        w = k % 2 ? 0.999 * w + 0.05 * normal(rng) : ((i / (300 + 37 * k)) % 2 ? 1.0 : 0.0);
        x[i] = w + 0.01 * normal(rng);
      }
      f.set("aux_extra_" + std::to_string(k), x);
    }
    magcomp::Model m = magcomp::load_model_yaml(argv[2]);
    magcomp::fit_model(m, {&f});
    const auto t0 = std::chrono::steady_clock::now();
    magcomp::DiagnoseOptions options;
    options.search_rails = !(argc > 4 && std::string(argv[4]) == "no-rails");
    const magcomp::Diagnosis dx = magcomp::diagnose(m, f, "mag_1_c", options);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    struct rusage ru {};
    getrusage(RUSAGE_SELF, &ru);
    std::printf(
        "samples %ld fields %zu candidates %zu terms_fitted %ld seconds %.2f peak_MB %.0f "
        "top %s\n",
        static_cast<long>(f.size()), f.names().size(), dx.candidates.size(), dx.candidates_tried, s,
        ru.ru_maxrss / 1024.0,
        dx.candidates.empty() ? "-" : dx.candidates.front().term.text().c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
}
