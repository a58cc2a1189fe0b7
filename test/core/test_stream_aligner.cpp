// The stream aligner: exact counts for every fault, interpolation, waiting and holding.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/stream/stream_aligner.h"

namespace magcomp {
namespace {

// Feeds sample k (t = 0.1 k) of a simple stream: scalar 100 + k, vector (k, 2k, 3k), aux cur = k.
struct Feeder {
  StreamAligner a;
  std::vector<AlignedSample> out;
  double wall = 0.0;
  Feeder() {
    a.select_channels({"cur"});
    a.wait_for(true, false);
  }
  void inputs(int k, double t) {
    a.add_vector(t, Eigen::Vector3d(k, 2.0 * k, 3.0 * k));
    a.add_aux(t, {"cur"}, {static_cast<double>(k)});
  }
  void scalar(double t, double value) {
    a.add_scalar(t, value, wall);
    step();
  }
  void step() {
    a.process(wall, false, false, [&](const AlignedSample& s) { out.push_back(s); });
  }
};

TEST(StreamAligner, CountsEveryFaultExactly) {
  Feeder f;
  for (int k = 0; k < 100; ++k) {
    if (k >= 50 && k < 80) continue;  // a 3 s gap
    const double t = 0.1 * k;
    f.inputs(k, t);
    f.scalar(t, k == 10 ? NAN : 100.0 + k);  // one NaN
    if (k == 20) f.scalar(t, 1.0);           // a duplicate stamp
    if (k == 30) f.scalar(t - 0.5, 1.0);     // 0.5 s back: out of order
  }
  f.a.add_vector(9.0, Eigen::Vector3d::Zero());   // an input older than the last: late
  f.a.add_aux(9.95, {"cur", "cur_heat"}, {1.0});  // names and values of different lengths
  EXPECT_EQ(f.a.add_scalar(1.0, 5.0, f.wall),
            StreamAligner::ScalarResult::kJumpedBack);  // 8.9 s back
  const AlignerCounts& c = f.a.counts();
  EXPECT_EQ(c.scalar_in, 73);  // 70 samples + duplicate + out of order + the jump
  EXPECT_EQ(c.nan_scalar, 1);
  EXPECT_EQ(c.duplicate_stamps, 1);
  EXPECT_EQ(c.out_of_order, 1);
  EXPECT_EQ(c.gaps, 1);
  EXPECT_EQ(c.jumps_back, 1);
  EXPECT_EQ(c.late_inputs, 1);
  EXPECT_EQ(c.aux_mismatch, 1);
  EXPECT_EQ(c.stale_inputs_held, 0);
  // Every accepted sample came out, in order, with its own inputs; the NaN passes as NaN.
  ASSERT_EQ(f.out.size(), 70u);
  for (const auto& s : f.out) {
    const int k = static_cast<int>(std::lround(s.t_s / 0.1));
    EXPECT_DOUBLE_EQ(s.vector_nT.y(), 2.0 * k);
    EXPECT_DOUBLE_EQ(s.channels[0], k);
    if (k == 10) {
      EXPECT_TRUE(std::isnan(s.scalar_nT));
    }
    EXPECT_EQ(s.starts_stream, k == 0 || k == 80) << k;
  }
  // After the jump the buffers are empty: the next sample waits for its own inputs.
  EXPECT_EQ(f.a.pending(), 1u);
  EXPECT_TRUE(std::isnan(f.a.last_vector_t()));
}

TEST(StreamAligner, InterpolatesBetweenInputsAndWaitsForTheStampToBeCovered) {
  Feeder f;
  f.inputs(0, 0.0);
  f.scalar(0.0, 100.0);
  f.a.add_scalar(0.05, 101.0, f.wall);  // between two inputs: not covered yet
  f.step();
  EXPECT_EQ(f.out.size(), 1u);
  f.a.add_vector(0.1, Eigen::Vector3d(10, 20, 30));
  f.step();
  EXPECT_EQ(f.out.size(), 1u) << "the aux message of 0.05 s has not come";
  f.a.add_aux(0.1, {"cur"}, {8.0});
  f.step();
  ASSERT_EQ(f.out.size(), 2u);
  EXPECT_DOUBLE_EQ(f.out[1].vector_nT.x(), 5.0);  // halfway
  EXPECT_DOUBLE_EQ(f.out[1].channels[0], 4.0);
  EXPECT_FALSE(f.out[1].stale);
  // At an input's own stamp: its value exactly.
  f.a.add_scalar(0.1, 102.0, f.wall);
  f.step();
  ASSERT_EQ(f.out.size(), 3u);
  EXPECT_DOUBLE_EQ(f.out[2].vector_nT.z(), 30.0);
  EXPECT_EQ(f.a.counts().stale_inputs_held, 0);
}

TEST(StreamAligner, HoldsTheLatestOnlyAfterWaitingInDataAndWallTime) {
  Feeder f;
  f.inputs(0, 0.0);
  f.scalar(0.0, 100.0);
  // The fluxgate stops; scalars go on.
  for (int k = 1; k <= 10; ++k) {
    f.a.add_aux(0.1 * k, {"cur"}, {static_cast<double>(k)});
    f.scalar(0.1 * k, 100.0 + k);
  }
  EXPECT_EQ(f.out.size(), 1u) << "data time is 1 s ahead, but no wall time has passed";
  f.wall = 0.6;  // now max_wait_s of wall time too
  f.step();
  // Samples more than 0.5 s before the last scalar (data time) are held; the later ones wait.
  EXPECT_EQ(f.out.size(), 5u);
  EXPECT_TRUE(f.out[4].stale);
  EXPECT_DOUBLE_EQ(f.out[4].vector_nT.x(), 0.0);  // the latest, held
  EXPECT_EQ(f.a.counts().stale_inputs_held, 4);
  // The end of the stream: the wall time alone decides.
  f.a.process(f.wall, true, false, [&](const AlignedSample& s) { f.out.push_back(s); });
  EXPECT_EQ(f.out.size(), 11u);
  EXPECT_EQ(f.a.counts().stale_inputs_held, 10);
}

TEST(StreamAligner, ForcedOutWithNoInputAtAllGivesNan) {
  StreamAligner a;
  a.add_scalar(1.0, 50000.0, 0.0);
  std::vector<AlignedSample> out;
  a.process(0.0, false, true, [&](const AlignedSample& s) { out.push_back(s); });
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(out[0].stale);
  EXPECT_TRUE(std::isnan(out[0].vector_nT.x()));
  EXPECT_TRUE(out[0].starts_stream);
}

}  // namespace
}  // namespace magcomp
