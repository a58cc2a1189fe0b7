// magcomp: a model's design matrix A over a flight, whole or in blocks (see model.h).
#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "magcomp/core/error.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/model/norm_remainder.h"

namespace magcomp {

Eigen::MatrixXd design_matrix(const Model& model, const FlightData& data) {
  return design_matrix(model, model.make_terms(), data);
}

Eigen::MatrixXd design_matrix(const Model& model, const std::vector<TermPtr>& terms,
                              const FlightData& data) {
  for (const auto& t : terms) {
    for (const auto& f : t->fields()) {
      if (!data.has(f)) {
        throw Error(data.source() + ": field '" + f + "' needed by term '" + t->spec() +
                    "' not found");
      }
    }
  }
  const TermInputs in = make_term_inputs(data, model.vector, model.bt_scale_nT);
  Eigen::Index cols = 0;
  for (const auto& t : terms) cols += t->columns();
  Eigen::MatrixXd a(data.size(), cols);
  Eigen::Index c = 0;
  double lag_s = 0.0;
  for (const auto& t : terms) {
    const Eigen::Index w = t->columns();
    t->build(in, a.middleCols(c, w));
    // The exact norm's column is the remainder of the model's own fitted TL.
    if (t->spec() == "norm" && model.fitted())
      a.col(c) = norm_remainder_nT(in, model.column_names, model.coefficients);
    c += w;
    lag_s += t->scalar_lag_s();
  }
  // The realigned scalar of a lagging sensor carries the round trip of a fractional shift: so do
  // the columns that model it.
  if (lag_s != 0.0 && data.size() > 1) lag_round_trip(a, lag_s / data.dt_s());
  return a;
}

Eigen::Index slice_margin(const Model& model, const std::vector<TermPtr>& terms, double dt_s) {
  int reach = 0;
  for (const auto& t : terms) {
    const int r = t->row_reach();
    if (r < 0) return -1;
    reach = std::max(reach, r);
  }
  const double lag_samples = std::abs(model.scalar_lag_s()) / dt_s;
  if (!std::isfinite(lag_samples) || lag_samples > 1e6) return -1;
  // +2: the cubic interpolation of a fractional shift reads two samples past the shifted one.
  // The columns' lag round trip reads a few rows each side, each needing the terms' reach.
  return reach + lag_round_trip_reach(lag_samples) +
         static_cast<Eigen::Index>(std::ceil(lag_samples)) + 2;
}

void for_each_design_block(
    const Model& model, const FlightData& data,
    const std::function<void(Eigen::Index, const Eigen::Ref<const Eigen::MatrixXd>&)>& block,
    int threads) {
  const auto terms = model.make_terms();
  const Eigen::Index n = data.size();
  const Eigen::Index margin = n > 1 ? slice_margin(model, terms, data.dt_s()) : -1;
  constexpr Eigen::Index kBlockRows = 16384;  // ~2.4 MB for 18 columns: stays in cache
  if (margin < 0 || n <= 2 * kBlockRows) {
    const Eigen::MatrixXd a = design_matrix(model, terms, data);
    block(0, a);
    return;
  }
  const Eigen::Index blocks = (n + kBlockRows - 1) / kBlockRows;
  std::atomic<Eigen::Index> next{0};
  std::mutex error_mutex;
  std::exception_ptr error;
  auto worker = [&] {
    for (Eigen::Index b; (b = next++) < blocks;) {
      try {
        const Eigen::Index first = b * kBlockRows;
        const Eigen::Index count = std::min(kBlockRows, n - first);
        const Eigen::Index lo = std::max<Eigen::Index>(0, first - margin);
        const Eigen::Index hi = std::min(n, first + count + margin);
        const FlightData part = data.rows(lo, hi - lo);
        const Eigen::MatrixXd a = design_matrix(model, terms, part);
        block(first, a.middleRows(first - lo, count));
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        next = blocks;  // no more blocks
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < std::min<Eigen::Index>(threads, blocks); ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace magcomp
