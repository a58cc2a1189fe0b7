// magcomp: whether a trained network's gain carries over to a flight (network_gain.h).
#include "magcomp/core/evaluate/network_gain.h"

#include <cmath>
#include <cstdio>

#include "magcomp/core/error.h"

namespace magcomp {

NetworkGain network_gain(const Model& model, const FlightData& data, const std::string& truth,
                         const Evaluation& with_network) {
  if (!model.neural || !model.neural->trained())
    throw Error(data.source() + ": the model has no trained network to weigh");
  Model physics = model;
  physics.neural.reset();
  return network_gain(evaluate_model(physics, data, truth, false), with_network, data.source());
}

NetworkGain network_gain(const Evaluation& physics, const Evaluation& with_network,
                         const std::string& flight) {
  NetworkGain g;
  g.physics = physics;
  const double p = physics.std_nT, w = with_network.std_nT;
  g.gain_std = p > 0 ? 1.0 - w / p : NAN;
  g.carries_over = g.gain_std >= kNetworkGainResolution;
  g.worse = g.gain_std <= -kNetworkGainResolution;
  char buf[320];
  if (g.carries_over) {
    std::snprintf(buf, sizeof(buf),
                  "the network's gain carries over to %s: std %.3f nT with it, %.3f nT with the "
                  "physical terms alone (%.0f %% lower)",
                  flight.c_str(), w, p, 100 * g.gain_std);
  } else if (g.worse) {
    std::snprintf(buf, sizeof(buf),
                  "the network's gain does not carry over to %s: std %.3f nT with it, %.3f nT "
                  "with the physical terms alone (%.0f %% higher): use the terms alone here",
                  flight.c_str(), w, p, -100 * g.gain_std);
  } else {
    std::snprintf(buf, sizeof(buf),
                  "the network gains nothing on %s: std %.3f nT with it, %.3f nT with the "
                  "physical terms alone",
                  flight.c_str(), w, p);
  }
  g.verdict = buf;
  return g;
}

}  // namespace magcomp
