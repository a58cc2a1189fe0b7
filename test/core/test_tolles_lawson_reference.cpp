// Tolles-Lawson verified against MagNav.jl's results on real flight data
// (test/data/reference/magnav_tl).
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/math/butterworth.h"
#include "magcomp/core/model/model.h"
#include "test_util.h"

namespace magcomp {
namespace {

struct Reference {
  FlightData flight;
  Eigen::MatrixXd series;  // flux_a_x, flux_a_y, flux_a_z, mag_1_uc, mag_1_comp, ..., mag_1_c
  std::vector<std::string> names;
};

Reference load_reference() {
  Reference r;
  r.series =
      test::read_csv(test::reference_dir() + "/magnav_tl/TL_data_timeseries.csv", true, &r.names);
  const Eigen::Index n = r.series.rows();
  r.flight.set("tt", Eigen::VectorXd::LinSpaced(n, 0.0, 0.1 * (n - 1)));
  r.flight.set("flux_a_x", r.series.col(0));
  r.flight.set("flux_a_y", r.series.col(1));
  r.flight.set("flux_a_z", r.series.col(2));
  r.flight.set("mag_1_uc", r.series.col(3));
  return r;
}

Model tl18() {
  Model m;
  m.scalar = "mag_1_uc";
  m.vector = "flux_a";
  m.terms = {"permanent", "induced", "eddy"};
  m.fit.lambda = 0.001;
  return m;
}

TEST(TollesLawsonReference, DesignMatrixEqualsMagNav) {
  const Reference r = load_reference();
  ASSERT_EQ(r.series.rows(), 1000);
  const Eigen::MatrixXd expected =
      test::read_csv(test::reference_dir() + "/magnav_tl/TL_data_A_a.csv", false);
  const Eigen::MatrixXd a = design_matrix(tl18(), r.flight);
  ASSERT_EQ(a.rows(), expected.rows());
  ASSERT_EQ(a.cols(), 18);
  double worst = 0;
  for (Eigen::Index i = 0; i < a.rows(); ++i) {
    for (Eigen::Index j = 0; j < a.cols(); ++j) {
      const double rel =
          std::abs(a(i, j) - expected(i, j)) / std::max(std::abs(expected(i, j)), 1e-12);
      worst = std::max(worst, rel);
    }
  }
  EXPECT_LT(worst, 1e-9) << "worst relative difference of the A matrix";
}

TEST(TollesLawsonReference, RidgeOnFilteredArraysGivesMagNavCoefficients) {
  const Eigen::MatrixXd af =
      test::read_csv(test::reference_dir() + "/magnav_tl/TL_data_A_a_f_t.csv", false);
  const Eigen::MatrixXd yf =
      test::read_csv(test::reference_dir() + "/magnav_tl/TL_data_mag_1_uc_f_t.csv", false);
  const Eigen::MatrixXd expected =
      test::read_csv(test::reference_dir() + "/magnav_tl/TL_data_TL_a_1.csv", false);
  ASSERT_EQ(af.rows(), 960);
  const Eigen::VectorXd c = ridge_solve(af, yf.col(0), 0.001);
  ASSERT_EQ(c.size(), 18);
  for (Eigen::Index j = 0; j < 18; ++j) {
    EXPECT_NEAR(c[j], expected(j, 0), 1e-6 * std::abs(expected(j, 0))) << "coefficient " << j;
  }
}

TEST(TollesLawsonReference, FullPipelineFromRawDataMatchesMagNavCompensation) {
  const Reference r = load_reference();
  Model m = tl18();
  m.fit.method = FitMethod::kBandpass;
  m.fit.windows = {{-1.0, 1e6}};
  m.fit.trim = 20;
  m.fit.order = 4;
  fit_model(m, {&r.flight});
  EXPECT_EQ(m.report.samples, 960);
  const Eigen::VectorXd comp = compensate(m, r.flight);
  const Eigen::VectorXd diff = comp - r.series.col(6);  // mag_1_c
  const double mean = diff.mean();
  const double sd = std::sqrt((diff.array() - mean).square().sum() / (diff.size() - 1));
  std::printf("  std(ours - MagNav mag_1_c) = %.4f nT\n", sd);
  EXPECT_LT(sd, 0.1);
  // Note: MagNav's band-passed arrays (TL_data_A_a_f_t.csv) differ from a standard zero-phase
  // Butterworth (ours, and scipy's sosfiltfilt, which ours equals to 1e-9) by ~32 % in norm;
  // the end-to-end compensation agrees within the 0.1 nT the reference README sets.
}

}  // namespace
}  // namespace magcomp
