// Simulator: closed-form physics, determinism, schema, and what TL can and cannot do on it.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include <yaml-cpp/yaml.h>
#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/error.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/geo/potential_field.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/sim/electrical.h"

#include "scenario_cache.h"

namespace magcomp {
namespace {

TEST(SimulatorPhysics, WireFieldMatchesClosedForms) {
  // A 2 km wire along x through the origin, point 1.5 m to the left (+y): |B| = mu0 I / (2 pi r),
  // pointing up (+z) for a current along +x (right-hand rule).
  const Eigen::Vector3d b = sim::wire_field_per_ampere_nT({-1000, 0, 0}, {1000, 0, 0}, {0, 1.5, 0});
  const double expected = 4e-7 * M_PI / (2 * M_PI * 1.5) * 1e9;  // nT per A
  EXPECT_NEAR(b.z(), expected, 2e-6 * expected);                 // 2 km vs infinite: 1.1e-6 shorter
  EXPECT_NEAR(b.x(), 0.0, 1e-12);
  EXPECT_NEAR(b.y(), 0.0, 1e-12);
  // Finite segment on its perpendicular bisector: mu0 I / (4 pi d) * 2 sin(theta).
  const double half = 0.3, d = 0.8;
  const Eigen::Vector3d s = sim::wire_field_per_ampere_nT({-half, 0, 0}, {half, 0, 0}, {0, 0, -d});
  const double finite = 100.0 / d * 2 * half / std::hypot(half, d);
  EXPECT_NEAR(s.norm(), finite, 1e-9 * finite);
  EXPECT_GT(s.y(), 0.0);  // x cross (-z) = +y
}

TEST(SimulatorPhysics, UpwardContinuationMatchesBuriedSource) {
  // The vertical field of a buried dipole-like source, f = d / (r^2 + d^2)^1.5, continues upward
  // by h into the same formula with depth d + h (harmonic in the upper half-space).
  const int n = 256;
  const double spacing = 50.0, depth = 500.0, up = 300.0;
  auto source = [&](double dd) {
    Eigen::MatrixXd g(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        const double x = (i - n / 2) * spacing, y = (j - n / 2) * spacing;
        g(i, j) = dd / std::pow(x * x + y * y + dd * dd, 1.5);
      }
    return g;
  };
  const std::vector<Eigen::MatrixXd> layers =
      upward_continue(source(depth), spacing, spacing, std::vector<double>{up / 2, up});
  const Eigen::MatrixXd& continued = layers[1];
  const Eigen::MatrixXd expected = source(depth + up);
  const double peak = expected.cwiseAbs().maxCoeff();
  const double err = (continued - expected).block(64, 64, 128, 128).cwiseAbs().maxCoeff();
  std::printf("  upward continuation: max error %.2e of the peak\n", err / peak);
  EXPECT_LT(err / peak, 1e-3);
  // Every layer of one transform is the single continuation to its height, and continuing twice
  // by h/2 is continuing by h (exp(-k h/2)^2 = exp(-k h)).
  EXPECT_EQ((layers[0] - upward_continue(source(depth), spacing, spacing, up / 2)).norm(), 0.0);
  const Eigen::MatrixXd twice = upward_continue(layers[0], spacing, spacing, up / 2);
  EXPECT_LT((twice - continued).cwiseAbs().maxCoeff() / peak, 1e-9);
}

TEST(Simulator, SameSeedSameFlightAndTheSchemaReadsBack) {
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/wire_strobe.yaml");
  s.segments.resize(1);  // the box only: quick
  const sim::Simulation a = sim::simulate(s, Igrf::installed()),
                        b = sim::simulate(s, Igrf::installed());
  ASSERT_EQ(a.flight.names(), b.flight.names());
  for (const auto& name : a.flight.names()) {
    const auto& x = a.flight.column(name);
    const auto& y = b.flight.column(name);
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      ASSERT_TRUE(x[i] == y[i] || (std::isnan(x[i]) && std::isnan(y[i]))) << name << " " << i;
    }
  }
  s.seed += 1;
  const sim::Simulation c = sim::simulate(s, Igrf::installed());
  EXPECT_NE(a.flight.column("mag_5_uc")[100], c.flight.column("mag_5_uc")[100]);
  const std::string dir = test::temp_dir("sim");
  sim::write_simulation(a, dir + "/f.h5");
  const FlightData r = read_flight_h5(dir + "/f.h5");
  EXPECT_NEAR(r.dt_s(), 0.1, 1e-9);
  for (const char* f :
       {"tt",        "line",     "flight",   "year",      "doy",      "lat",        "lon",
        "utm_x",     "utm_y",    "utm_z",    "msl",       "baro",     "radar",      "topo",
        "ins_pitch", "ins_roll", "ins_yaw",  "diurnal",   "mag_1_c",  "mag_1_igrf", "mag_1_uc",
        "mag_5_uc",  "flux_a_x", "flux_d_t", "ins_vn",    "ins_vw",   "ins_vu",     "pitch_rate",
        "tas",       "cur_strb", "cur_tank", "vol_bat_1", "static_p", "drape"}) {
    EXPECT_TRUE(r.has(f)) << f;
  }
  EXPECT_TRUE(std::ifstream(dir + "/f.truth.yaml").good());
  EXPECT_TRUE(read_flight_h5(dir + "/f.truth.h5").has("mag_5_uc.hidden.0.wire"));
  // The IGRF along the track is IGRF-14 (mag_1_dc - mag_1_igrf = the IGRF total).
  const double igrf_total = r.column("mag_1_dc")[0] - r.column("mag_1_igrf")[0];
  EXPECT_GT(igrf_total, 52000.0);
  EXPECT_LT(igrf_total, 56000.0);
}

// The aircraft's non-electrical states (aircraft.states): recorded beside the electrical
// channels from their own random stream, so that every other channel and the scalar are the
// same; the outside air temperature follows the altitude (15 degC - 6.5 degC/km, lagged 20 s),
// the flaps sit at 0, 10 or 20 deg, the switch is 0 or 1; a product with a state is an effect
// the scenario file accepts.
TEST(Simulator, TheAircraftsStatesAreRecordedWithoutChangingTheRestOfTheFlight) {
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/lag.yaml");
  const sim::Simulation plain = sim::simulate(s, Igrf::installed());
  s.aircraft_states = true;
  const sim::Simulation with = sim::simulate(s, Igrf::installed());
  for (const std::string& c : sim::simulated_state_channels()) {
    EXPECT_FALSE(plain.flight.has(c)) << c;
    ASSERT_TRUE(with.flight.has(c)) << c;
  }
  for (const char* c : {"cur_strb", "vol_bat_1", "mag_5_uc", "flux_c_x", "ins_roll"})
    EXPECT_EQ(Eigen::VectorXd(plain.flight.column(c)), Eigen::VectorXd(with.flight.column(c))) << c;
  const FlightData& f = with.flight;
  const auto oat = f.column("oat_degC"), msl = f.column("msl"), flap = f.column("flap_deg");
  const auto sw = f.column("sw_pitot_heat");
  double worst = 0, lo = INFINITY, hi = -INFINITY;
  for (Eigen::Index i = 600; i < f.size(); ++i) {  // past the probe's start-up
    worst = std::max(worst, std::abs(oat[i] - (15.0 - 6.5e-3 * msl[i])));
    lo = std::min(lo, flap[i]);
    hi = std::max(hi, flap[i]);
    EXPECT_TRUE(sw[i] == 0.0 || sw[i] == 1.0);
  }
  // The probe's 20 s lag at a 5 m/s climb: 0.65 degC; msl is above the geoid, the model's
  // altitude above the ellipsoid (tens of metres here): under 1.5 degC in all.
  EXPECT_LT(worst, 1.5);
  EXPECT_GT(lo, -0.5);
  EXPECT_LT(hi, 20.5);
  const std::string dir = test::temp_dir("states");
  std::ofstream(dir + "/s.yaml")
      << "seed: 3\naircraft: {states: true}\nplan:\n  - {type: line, line: 1.0, duration_s: 60}\n"
         "hidden:\n  - {type: product, channel: cur_strb, channel2: flap_deg, gain: 0.1}\n";
  EXPECT_TRUE(sim::load_scenario(dir + "/s.yaml").aircraft_states);
  std::ofstream(dir + "/t.yaml")
      << "seed: 3\nplan:\n  - {type: line, line: 1.0, duration_s: 60}\n"
         "hidden:\n  - {type: product, channel: cur_strb, channel2: flap_deg, gain: 0.1}\n";
  EXPECT_THROW(sim::load_scenario(dir + "/t.yaml"), Error);
}

TEST(Simulator, IdealTollesLawsonReachesTheSensorFloorOnTheTlOnlyFlight) {
  // With every coefficient known from the truth (a reference fit on the whole flight), TL leaves
  // only the sensor noise: mag_5 and mag_1_c cesium noise (0.005 nT each), fluxgate noise
  // propagated through the TL columns, and the dropped second-order term (~0.01 nT here).
  const FlightData& f = test::scenario("tl_only").flight;
  Model m = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  m.add_term("bias");
  m.fit.method = FitMethod::kReference;
  m.fit.reference = "mag_1_c";
  m.fit.lines.clear();
  m.fit.lambda = 0.0;
  fit_model(m, {&f});
  const double ideal = evaluate_model(m, f, "mag_1_c").std_nT;
  const double floor = std::sqrt(2.0) * 0.005;
  std::printf("  ideal TL %.4f nT, cesium floor %.4f nT\n", ideal, floor);
  EXPECT_LT(ideal, 2.0 * floor);
}

TEST(Simulator, BoxCalibratedTlIsLimitedByTheInducedFieldScalingWithTheAnomaly) {
  // A box flown at constant |B| cannot separate the induced field's scaling with |B| (sum of
  // B̂i² = 1): over the crustal anomaly (|B| varies by hundreds of nT at 400 m) that leaves
  // ~0.26 nT, and the residual follows the fluxgate total.
  const FlightData& f = test::scenario("tl_only").flight;
  const double tl = test::tl_std(f);
  std::printf("  box-calibrated TL on tl_only: %.3f nT\n", tl);
  EXPECT_LT(tl, 0.4);
  const Diagnosis dx = diagnose(test::calibrated_tl(f), f, "mag_1_c");
  ASSERT_FALSE(dx.associations.empty());
  EXPECT_EQ(dx.associations.front().channel.substr(0, 5), "flux_");
  EXPECT_GT(std::abs(dx.associations.front().spearman), 0.5);
}

TEST(Simulator, HiddenEffectsLeaveClearlyMoreAndTheTruthAccountsForTheExcess) {
  const double floor = test::tl_std(test::scenario("tl_only").flight);
  for (const char* name : {"wire_strobe", "fuel_pump_wire", "inductive_heater", "lag"}) {
    const sim::Simulation& s = test::scenario(name);
    const double with_hidden = test::tl_std(s.flight);
    // The same flight with the truth file's hidden contributions removed from mag 5.
    FlightData cleaned = s.flight;
    Eigen::VectorXd mag5 = cleaned.column("mag_5_uc");
    for (const auto& col : s.truth.names()) {
      if (col.rfind("mag_5_uc.hidden.", 0) == 0) mag5 -= s.truth.column(col);
    }
    cleaned.set("mag_5_uc", mag5);
    const double without = test::tl_std(cleaned);
    std::printf("  %-18s TL std %.3f nT, hidden removed %.3f nT (tl_only %.3f)\n", name,
                with_hidden, without, floor);
    EXPECT_GT(with_hidden, 5.0 * floor) << name;
    EXPECT_LT(without, 1.2 * floor) << name;
  }
}

// A lag of a fraction of a sample (0.25 s at 10 Hz) cannot be undone on the 10 Hz record, but a
// model with lag:0.25 predicts what the realigned sensor reads (the columns' lag round trip) and
// reaches the same error as the whole-sample lag of the shipped `lag` flight.
TEST(Simulator, AFractionalLagIsCompensatedAsWellAsAWholeSampleOne) {
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/lag.yaml");
  ASSERT_EQ(s.hidden.size(), 1u);
  s.hidden[0].lag_s = 0.25;
  const sim::Simulation fractional = sim::simulate(s, Igrf::installed());
  const double whole = test::tl_std(test::scenario("lag").flight, {"lag:0.3"});
  const double frac = test::tl_std(fractional.flight, {"lag:0.25"});
  // The scalar realigned by hand and TL fitted on it: the columns miss the round trip.
  FlightData realigned = fractional.flight;
  realigned.set("mag_5_uc", shift_samples(realigned.column("mag_5_uc"), -2.5));
  const double by_hand = test::tl_std(realigned);
  std::printf(
      "  TL + lag: 0.3 s (3 samples) %.3f nT, 0.25 s (2.5 samples) %.3f nT; TL on the "
      "scalar realigned by 0.25 s %.3f nT\n",
      whole, frac, by_hand);
  EXPECT_LT(frac, 1.05 * whole);
  EXPECT_LT(whole, 0.3);
  EXPECT_GT(by_hand, 1.1 * frac);
}

TEST(Simulator, MultiFlightSetSharesOneAircraftAndHeadingErrorIsAbsorbedByTl) {
  std::vector<std::vector<double>> permanent;
  for (const char* name : {"multi/flt2001_calibration", "multi/flt2003_survey_grid"}) {
    sim::Scenario s =
        sim::load_scenario(test::source_dir() + "/config/scenarios/" + name + ".yaml");
    s.segments.resize(1);
    const YAML::Node truth = YAML::Load(sim::simulate(s, Igrf::installed()).truth_yaml);
    permanent.push_back(truth["sensors"]["mag_5_uc"]["permanent_nT"].as<std::vector<double>>());
  }
  EXPECT_EQ(permanent[0], permanent[1]);  // aircraft.seed: the same aircraft on every flight
  // A cesium heading error (∝ cos of the field-to-axis angle) lies in the permanent term's span.
  const double floor = test::tl_std(test::scenario("tl_only").flight);
  const double heading = test::tl_std(test::scenario("heading_error").flight);
  std::printf("  heading_error: TL std %.3f nT (tl_only %.3f)\n", heading, floor);
  EXPECT_LT(heading, 1.2 * floor);
}

TEST(Simulator, BadScenarioFilesNameTheKey) {
  const std::string dir = test::temp_dir("scn");
  const std::string base =
      "plan:\n  - {type: line, line: 1001.1, heading_deg: 0, duration_s: 60}\n";
  auto message = [&](const std::string& text) -> std::string {
    std::ofstream(dir + "/s.yaml") << text;
    try {
      sim::load_scenario(dir + "/s.yaml");
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(message(base + "speed: 3\n").find("'speed'"), std::string::npos);
  EXPECT_NE(message(base + "hidden:\n  - {type: wire, channel: cur_nope}\n").find("cur_nope"),
            std::string::npos);
  EXPECT_NE(message(base + "sensors: {scalar_noise_nT: -1}\n").find("sensors.scalar_noise_nT"),
            std::string::npos);
  EXPECT_NE(message(base + "seed: [1, 2]\n").find("'seed'"), std::string::npos);
  EXPECT_NE(message(base + "hidden:\n  - {type: wire, channel: cur_strb, colour: red}\n")
                .find("hidden[0].colour"),
            std::string::npos);
  EXPECT_NE(message("seed: 1\n").find("'plan'"), std::string::npos);
  EXPECT_NE(message(base + base).find("'plan' given twice"), std::string::npos);
  EXPECT_EQ(message(base), "");
}

}  // namespace
}  // namespace magcomp
