// The exact norm (`norm`): TL's vector field read from its coefficients, the remainder its
// first-order expansion drops, and the fit that sizes it from TL's own coefficients.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/model/norm_remainder.h"
#include "magcomp/core/sim/simulator.h"
#include "test_util.h"

namespace magcomp {
namespace {

// The base flight of the shipped random scenario (no hidden effect), aircraft 77, flight `seed`.
sim::Simulation base_flight(unsigned seed) {
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  s.aircraft_seed = 77;
  s.seed = seed;
  return sim::simulate(s, Igrf::installed());
}

// A model of TL's 18 columns (and `extra` terms) on the simulator's cabin sensor.
Model tl_model(const std::vector<std::string>& extra, FitMethod method, double lambda) {
  Model m = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  for (const std::string& t : extra) m.add_term(TermSpec(t));
  m.fit.method = method;
  m.fit.lambda = lambda;
  if (method == FitMethod::kReference) m.fit.reference = "mag_1_c";
  return m;
}

// An aircraft field as TL's coefficients (permanent nT, induced and eddy per Bt scale), sizes of
// a real cabin sensor (hundreds of nT), with the induced matrix symmetric.
Model with_known_tl(Model m) {
  m.column_names = m.make_column_names();
  m.coefficients = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(m.column_names.size()));
  const double known[18] = {180.0, -260.0, 95.0,                         // permanent, nT
                            900.0, -300.0, 150.0, -700.0, 240.0, 500.0,  // induced xx..zz
                            40.0,  -25.0,  10.0,  30.0,   -60.0, 15.0,  -5.0, 20.0, 45.0};  // eddy
  for (Eigen::Index k = 0; k < 18; ++k) m.coefficients[k] = known[k];
  return m;
}

TEST(ExactNorm, TlTimesItsCoefficientsIsTheVectorFieldAlongTheSensorsDirection) {
  // TL's columns times its coefficients are B̂·v exactly, v the vector field read back from the
  // coefficients (an off-diagonal induced coefficient split evenly): the reading is the columns'
  // own algebra, checked here row by row, and the remainder is the exact norm's change less it,
  // close to the second-order closed form (|v|² - (B̂·v)²) / (2|B|).
  const sim::Simulation f = base_flight(5);
  const Model m = with_known_tl(tl_model({}, FitMethod::kBandpass, 1e-4));
  const Eigen::MatrixXd a = design_matrix(m, f.flight);
  const Eigen::VectorXd first_order = a * m.coefficients;
  const TermInputs in = make_term_inputs(f.flight, m.vector, m.bt_scale_nT);
  const Eigen::MatrixX3d v = tl_vector_field_nT(in, m.column_names, m.coefficients);
  const Eigen::VectorXd remainder = norm_remainder_nT(in, m.column_names, m.coefficients);
  double worst_first = 0, worst_second = 0, rms = 0;
  for (Eigen::Index r = 0; r < in.direction.rows(); ++r) {
    const Eigen::Vector3d b = in.field_nT.row(r).transpose(), u = v.row(r).transpose();
    worst_first = std::max(worst_first, std::abs(first_order[r] - b.normalized().dot(u)));
    const double exact = (b + u).norm() - b.norm() - b.normalized().dot(u);
    EXPECT_NEAR(remainder[r], exact, 1e-9) << "row " << r;
    const double closed = (u.squaredNorm() - std::pow(b.normalized().dot(u), 2)) / (2 * b.norm());
    worst_second = std::max(worst_second, std::abs(remainder[r] - closed));
    rms += remainder[r] * remainder[r];
  }
  rms = std::sqrt(rms / static_cast<double>(remainder.size()));
  std::printf("  |v| up to %.0f nT: remainder rms %.3f nT, off the closed form by %.2e nT\n",
              v.rowwise().norm().maxCoeff(), rms, worst_second);
  EXPECT_LT(worst_first, 1e-9);
  EXPECT_GT(rms, 0.1);                  // a remainder TL cannot ignore at these sizes
  EXPECT_LT(worst_second, 0.02 * rms);  // third order in |v|/|B|
}

TEST(ExactNorm, AFitOfTheNormRecoversAKnownAircraftField) {
  // The scalar replaced by the exact norm |B + v| of a known vector field v (the fluxgate's B,
  // no noise) and the reference by |B|: TL with `norm` fitted against the reference recovers v's
  // coefficients and leaves nothing; plain TL leaves the remainder's part outside its columns.
  sim::Simulation f = base_flight(5);
  const Model truth = with_known_tl(tl_model({}, FitMethod::kBandpass, 1e-4));
  const TermInputs in = make_term_inputs(f.flight, truth.vector, truth.bt_scale_nT);
  const Eigen::MatrixX3d v = tl_vector_field_nT(in, truth.column_names, truth.coefficients);
  f.flight.set(truth.scalar, (in.field_nT + v).rowwise().norm());
  f.flight.set("mag_1_c", in.total_nT);
  Model plain = tl_model({"bias"}, FitMethod::kReference, 1e-9);
  Model exact = tl_model({"bias", "norm"}, FitMethod::kReference, 1e-9);
  fit_model(plain, {&f.flight});
  fit_model(exact, {&f.flight});
  const double plain_nT = evaluate_model(plain, f.flight, "mag_1_c", false).std_nT;
  const double exact_nT = evaluate_model(exact, f.flight, "mag_1_c", false).std_nT;
  std::printf("  error, line means removed: TL %.4f nT, TL as the exact norm %.6f nT (norm %.4f)\n",
              plain_nT, exact_nT, exact.coefficients[exact.coefficients.size() - 1]);
  EXPECT_GT(plain_nT, 0.02);
  EXPECT_LT(exact_nT, 1e-3);
  EXPECT_NEAR(exact.coefficients[exact.coefficients.size() - 1], 1.0, 1e-3);
  for (Eigen::Index k = 0; k < 18; ++k)
    EXPECT_NEAR(exact.coefficients[k], truth.coefficients[k],
                1e-3 * std::abs(truth.coefficients[k]) + 1e-2)
        << exact.column_names[static_cast<size_t>(k)];
}

TEST(ExactNorm, TheSimulatedAircraftsNextFlightFallsToTheSensorsNoise) {
  // The simulator's scalar is the exact norm of the Earth's field plus the aircraft's; TL leaves
  // 0.1-0.2 nT on the next flight. Written as the exact norm and fitted against the stinger on
  // the same two calibration segments (four minutes), the next flight falls to about the scalar
  // sensor's 0.005 nT noise and the fluxgate's; the band-pass alone sizes it less well.
  const sim::Simulation fa = base_flight(5), fb = base_flight(6);
  Model tl = tl_model({}, FitMethod::kBandpass, 1e-4);
  Model band_norm = tl_model({"norm"}, FitMethod::kBandpass, 1e-4);
  Model reference_tl = tl_model({"bias"}, FitMethod::kReference, 1e-6);
  Model reference_norm = tl_model({"bias", "norm"}, FitMethod::kReference, 1e-6);
  for (Model* m : {&tl, &band_norm, &reference_tl, &reference_norm}) fit_model(*m, {&fa.flight});
  const auto next = [&](const Model& m) {
    return evaluate_model(m, fb.flight, "mag_1_c", false).std_nT;
  };
  std::printf(
      "  next flight: TL %.4f nT (band-pass), %.4f nT (reference); TL as the exact norm %.4f nT "
      "(band-pass), %.4f nT (reference)\n",
      next(tl), next(reference_tl), next(band_norm), next(reference_norm));
  EXPECT_GT(next(tl), 0.1);
  EXPECT_GT(next(reference_tl), 0.1);
  EXPECT_LT(next(band_norm), 0.8 * next(tl));
  EXPECT_LT(next(reference_norm), 0.02);
}

}  // namespace
}  // namespace magcomp
