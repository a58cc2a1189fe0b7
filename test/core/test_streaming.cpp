// The streaming compensator reproduces the batch compensation sample for sample.
#include <gtest/gtest.h>

#include <chrono>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/stream/streaming_compensator.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

// Streams the whole two_effects flight through a TL + current model with `lag` and compares
// every output with the batch compensation.
void expect_stream_equals_batch(const std::string& lag) {
  const FlightData& f = test::scenario("two_effects").flight;
  const Model m = test::calibrated_tl(f, {"current:cur_strb", lag});
  const Eigen::VectorXd batch = compensate(m, f);
  StreamingCompensator sc(m);
  ASSERT_EQ(sc.required_channels(), std::vector<std::string>{"cur_strb"});
  std::vector<StreamOutput> out;
  const auto t0 = std::chrono::steady_clock::now();
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    const StreamSample s = test::sample_at(f, i, {"cur_strb"});
    for (const auto& o : sc.push(s)) out.push_back(o);
  }
  const double per_sample_us =
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count() /
      static_cast<double>(f.size());
  std::printf("  lookahead %d samples, %.1f us per sample\n", sc.lookahead(), per_sample_us);
  EXPECT_EQ(sc.lookahead(), 6);  // 0.27 or 0.3 s lag at 10 Hz: ceil(3) + 1 + 2
  for (const auto& o : sc.flush()) out.push_back(o);
  ASSERT_EQ(static_cast<Eigen::Index>(out.size()), f.size());
  double worst = 0;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    ASSERT_DOUBLE_EQ(out[static_cast<size_t>(i)].t_s, f.tt()[i]);
    const double a = out[static_cast<size_t>(i)].compensated_nT, b = batch[i];
    if (std::isnan(b)) {
      EXPECT_TRUE(std::isnan(a)) << i;
      continue;
    }
    worst = std::max(worst, std::abs(a - b));
  }
  EXPECT_LT(worst, 1e-6);
  std::printf("  worst |stream - batch| = %.2e nT\n", worst);
}

TEST(Streaming, WholeFlightEqualsBatchWithCurrentsAndLag) { expect_stream_equals_batch("lag:0.3"); }

// A fractional lag gives the columns its round trip (lag_round_trip): the stream reads the rows
// it needs around each sample and still equals the batch.
TEST(Streaming, WholeFlightEqualsBatchWithAFractionalLag) {
  expect_stream_equals_batch("lag:0.27");
}

TEST(Streaming, NanInputsGiveNanOutputsAndTheStreamGoesOn) {
  const FlightData& f = test::scenario("tl_only").flight;
  const Model m = test::calibrated_tl(f);
  StreamingCompensator sc(m);
  int nan_out = 0, finite_out = 0;
  for (Eigen::Index i = 0; i < 200; ++i) {
    StreamSample s;
    s.t_s = f.tt()[i];
    s.scalar_nT = i == 50 ? std::numeric_limits<double>::quiet_NaN() : f.column("mag_5_uc")[i];
    s.vector_nT = {f.column("flux_c_x")[i], f.column("flux_c_y")[i], f.column("flux_c_z")[i]};
    if (i == 120) s.vector_nT.x() = std::numeric_limits<double>::quiet_NaN();
    for (const auto& o : sc.push(s)) (std::isfinite(o.compensated_nT) ? finite_out : nan_out)++;
  }
  for (const auto& o : sc.flush()) (std::isfinite(o.compensated_nT) ? finite_out : nan_out)++;
  EXPECT_EQ(finite_out + nan_out, 200);
  // The NaN scalar spoils its own sample; the NaN vector its own and its two difference neighbours.
  EXPECT_EQ(nan_out, 4);
}

}  // namespace
}  // namespace magcomp
