// magcomp simulator: a whole flight in the MIT challenge schema, with its truth.
#pragma once

#include <string>

#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/sim/scenario.h"

namespace magcomp::sim {

/// A simulated flight: the data a user sees, and the truth behind it.
struct Simulation {
  FlightData flight;  ///< MIT schema (DATA.md): tt, line, INS, mags, fluxgates, channels, ...
  FlightData
      truth;  ///< per-sample contributions: `<sensor>.aircraft`, `<sensor>.hidden.<k>.<type>`,
              ///< `<sensor>.noise`, `<flux>.clean_x/y/z`, `earth_total`, ... (nT)
  std::string truth_yaml;  ///< the effects, their parameters, their rms contribution per sensor
  /// With the scenario's navigation.map: the anomaly the flight samples, on a latitude/longitude
  /// grid at the flight's mean height (cell = the anomaly grid's), empty otherwise.
  nav::AnomalyMap map;
};

/// The map file written beside a flight F.h5: F.map.h5.
std::string map_path(const std::string& out_h5);

/// Simulates the scenario. The physics is computed as vectors and exact norms (never with the
/// Tolles-Lawson linearisation): Earth field (the main field `igrf`, e.g. Igrf::installed(), +
/// upward-continued crustal anomaly +
/// diurnal) rotated into the body, plus each sensor's permanent, induced and eddy aircraft field,
/// plus the hidden effects. Deterministic in scenario.seed.
Simulation simulate(const Scenario& scenario, const Igrf& igrf);

/// The term of magcomp's language that writes hidden effect `e` on a scalar sensor exactly, its
/// coefficients left to the fit ("current:cur_strb", "field:cur_heat|pow(2)|lp(240)", "lag:0.2");
/// "" for an effect no term writes (a ripple of unrecorded phase, a saturating core, a heading
/// error, a fluxgate fault). The truth file's `expected_term`.
std::string expected_term(const HiddenEffect& e);

/// Writes F.h5 and, beside it, F.truth.h5 and F.truth.yaml (each atomically).
void write_simulation(const Simulation& sim, const std::string& out_h5,
                      const std::vector<std::string>& inputs = {});

/// Path of the truth files for a flight file: `F.h5` -> `F.truth.yaml` / `F.truth.h5`.
std::string truth_path(const std::string& out_h5, const std::string& extension);

}  // namespace magcomp::sim
