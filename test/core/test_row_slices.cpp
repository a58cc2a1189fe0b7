// magcomp tests: work on slices of rows (calibration segments, blocks of a long flight, partial
// HDF5 reads) gives the same numbers, bit for bit, as the same work on the whole flight.
#include <gtest/gtest.h>

#include <mutex>

#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"
#include "synthetic_flight.h"
#include "test_util.h"

namespace magcomp {
namespace {

Model tl_with_lag_and_wire() {
  Model m;
  m.scalar = "mag_5_uc";
  m.vector = "flux_c";
  m.terms = {"permanent", "induced", "eddy"};
  m.fit.lambda = 1e-6;
  m.fit.lines = {1000.01, 1002.01};  // two of the four legs
  return m;
}

// 80,000 samples (several 16,384-row blocks), a wire current and a 0.23 s scalar lag.
FlightData long_flight() {
  const Eigen::VectorXd c = Eigen::VectorXd::LinSpaced(18, -40.0, 60.0);
  FlightData d = test::synthetic_tl_flight(tl_with_lag_and_wire(), c, 80000);
  Eigen::VectorXd current(d.size());
  for (Eigen::Index i = 0; i < d.size(); ++i) current[i] = 2.0 + std::sin(0.013 * i) * (i % 7);
  d.set("cur_strb", current);
  d.set("mag_1_c", (d.column("mag_1_c").array() + 0.5 * current.array()).matrix().eval());
  return d;
}

TEST(RowSlices, ASliceReadsTheParentsRowsAndKeepsItsSamplePeriod) {
  const Model m = tl_with_lag_and_wire();
  const FlightData d = long_flight();
  const FlightData part = d.rows(1000, 37);
  ASSERT_EQ(part.size(), 37);
  EXPECT_EQ(part.dt_s(), d.dt_s());
  EXPECT_EQ(part.column("flux_c_y"), d.column("flux_c_y").segment(1000, 37));
  EXPECT_EQ(d.column_rows("cur_strb", 5, 9), d.column("cur_strb").segment(5, 9));
  EXPECT_THROW(d.rows(79990, 11), Error);
}

TEST(RowSlices, DesignBlocksEqualTheWholeMatrixBitForBit) {
  Model m = tl_with_lag_and_wire();
  m.terms = {"permanent", "induced", "eddy", "lag:0.23", "current:cur_strb", "fdm"};
  const FlightData d = long_flight();
  const Eigen::MatrixXd whole = design_matrix(m, d);
  Eigen::MatrixXd assembled(whole.rows(), whole.cols());
  Eigen::Index covered = 0, blocks = 0;
  for_each_design_block(m, d, [&](Eigen::Index first, const Eigen::Ref<const Eigen::MatrixXd>& a) {
    EXPECT_EQ(first, covered);
    assembled.middleRows(first, a.rows()) = a;
    covered += a.rows();
    ++blocks;
  });
  EXPECT_EQ(covered, d.size());
  EXPECT_GT(blocks, 1);  // the flight is long enough to be cut
  EXPECT_TRUE((assembled.array() == whole.array() ||
               (assembled.array() != assembled.array() && whole.array() != whole.array()))
                  .all());
  // On three threads: every row once, the same numbers, whatever the order the blocks come in.
  Eigen::MatrixXd threaded = Eigen::MatrixXd::Constant(whole.rows(), whole.cols(), 7.0);
  std::mutex mutex;
  Eigen::Index rows_seen = 0;
  for_each_design_block(
      m, d,
      [&](Eigen::Index first, const Eigen::Ref<const Eigen::MatrixXd>& a) {
        threaded.middleRows(first, a.rows()) = a;  // disjoint rows: no lock needed
        std::lock_guard<std::mutex> lock(mutex);
        rows_seen += a.rows();
      },
      3);
  EXPECT_EQ(rows_seen, d.size());
  EXPECT_TRUE((threaded.array() == whole.array() ||
               (threaded.array() != threaded.array() && whole.array() != whole.array()))
                  .all());
  // An error in one block is the caller's, once.
  EXPECT_THROW(for_each_design_block(
                   m, d,
                   [&](Eigen::Index first, const Eigen::Ref<const Eigen::MatrixXd>&) {
                     if (first > 0) throw Error("block failed");
                   },
                   2),
               Error);
  // A term with a history (a causal low-pass) is built whole, in one block.
  m.terms.push_back("field:cur_strb|lp(20)");
  int history_blocks = 0;
  for_each_design_block(
      m, d, [&](Eigen::Index, const Eigen::Ref<const Eigen::MatrixXd>&) { ++history_blocks; });
  EXPECT_EQ(history_blocks, 1);
}

TEST(RowSlices, TheFitOnSegmentsEqualsTheFitOnTheWholeMatrix) {
  Model m = tl_with_lag_and_wire();
  m.terms = {"permanent", "induced", "eddy", "lag:0.23", "current:cur_strb"};
  const FlightData d = long_flight();
  Model fitted = m;
  fit_model(fitted, {&d});
  // The same fit from the whole flight's design matrix, by the documented steps.
  const Eigen::MatrixXd a = design_matrix(m, d);
  const Eigen::VectorXd y = fit_target(m, d);
  const auto runs = calibration_runs(m.fit, d, a, y, nullptr);
  ASSERT_EQ(runs.size(), 2u);
  const Eigen::MatrixXd af = stack_runs(m.fit, d.dt_s(), a, runs);
  const Eigen::VectorXd yf = stack_runs(m.fit, d.dt_s(), y, runs).col(0);
  EXPECT_EQ(fitted.coefficients, ridge_solve(af, yf, m.fit.lambda));
  EXPECT_EQ(fitted.report.samples, af.rows());
}

TEST(RowSlices, AFileIsReadOnlyWhereTheJobNeedsItAndGivesTheSameNumbers) {
  Model m = tl_with_lag_and_wire();
  m.terms = {"permanent", "induced", "eddy", "lag:0.23", "current:cur_strb"};
  const FlightData d = long_flight();
  const std::string path = test::temp_dir("row_slices") + "/flight.h5";
  write_flight_h5(d, path);

  const FlightData from_file = read_flight_h5(path);
  const size_t at_open = from_file.loaded_columns();
  Model fitted_file = m, fitted_memory = m;
  fit_model(fitted_file, {&from_file});
  fit_model(fitted_memory, {&d});
  EXPECT_EQ(fitted_file.coefficients, fitted_memory.coefficients);
  // The fit reads tt and line whole, the scalar, fluxgate and current only around the segments.
  EXPECT_EQ(from_file.loaded_columns(), std::max<size_t>(at_open, 2));

  const Evaluation on_file = evaluate_model(fitted_file, from_file, "mag_1_c");
  const Evaluation in_memory = evaluate_model(fitted_memory, d, "mag_1_c");
  EXPECT_EQ(on_file.std_nT, in_memory.std_nT);
  EXPECT_EQ(on_file.rmse_nT, in_memory.rmse_nT);
  EXPECT_EQ(on_file.n, in_memory.n);
  EXPECT_GT(on_file.n, 79000);
}

}  // namespace
}  // namespace magcomp
