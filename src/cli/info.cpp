// magcomp info: what a flight file holds, field by field (every column read, so a corrupt one is
// found here rather than halfway through a job).
#include <cmath>
#include <cstdio>
#include <limits>

#include "common.h"
#include "subcommands.h"

namespace magcomp::cli {

void add_info(CLI::App& app) {
  auto* cmd = app.add_subcommand("info", "list a flight file's fields: samples, NaN, range");
  auto data = std::make_shared<std::string>();
  cmd->add_option("--data", *data, "flight HDF5 file")->required();
  cmd->callback([=] {
    const FlightData flight = read_flight(*data);
    std::printf("%s: %ld samples", data->c_str(), static_cast<long>(flight.size()));
    if (flight.size() > 1) {
      std::printf(", tt %.3f .. %.3f s, sample period %.6g s", flight.tt()[0],
                  flight.tt()[flight.size() - 1], flight.dt_s());
    }
    std::printf(", %zu fields\n", flight.names().size());
    std::printf("%-20s %10s %16s %16s\n", "field", "nan", "min", "max");
    for (const std::string& name : flight.names()) {
      const auto v = flight.column(name);
      long nan = 0;
      double lo = std::numeric_limits<double>::infinity(), hi = -lo;
      for (Eigen::Index i = 0; i < v.size(); ++i) {
        if (std::isnan(v[i])) {
          ++nan;
          continue;
        }
        lo = std::min(lo, v[i]);
        hi = std::max(hi, v[i]);
      }
      std::printf("%-20s %10ld %16s %16s\n", name.c_str(), nan, figure(lo, "%.6g").c_str(),
                  figure(hi, "%.6g").c_str());
    }
  });
}

}  // namespace magcomp::cli
