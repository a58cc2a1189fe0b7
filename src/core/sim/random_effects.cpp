// magcomp simulator: random hidden effects (random_effects.h).
#include "magcomp/core/sim/random_effects.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>

#include "magcomp/core/error.h"
#include "magcomp/core/sim/simulator.h"

namespace magcomp::sim {
namespace {

const std::vector<std::string> kCurrents = {
    "cur_com_1",  "cur_ac_hi",  "cur_ac_lo", "cur_tank",  "cur_flap",   "cur_strb",  "cur_srvo_o",
    "cur_srvo_m", "cur_srvo_i", "cur_heat",  "cur_acpwr", "cur_outpwr", "cur_bat_1", "cur_bat_2"};
const std::vector<std::string> kVoltages = {"vol_acpwr", "vol_outpwr", "vol_bat_1",
                                            "vol_bat_2", "vol_block",  "vol_back",
                                            "vol_srvo",  "vol_cabt",   "vol_fan"};
const std::vector<std::string> kInsChannels = {"nrml_acc", "pitch_rate", "roll_rate", "yaw_rate"};
const std::vector<std::string> kKinds = {"wire",   "inductive", "drift",      "thermal", "relay",
                                         "ripple", "product",   "hysteresis", "flex",    "lag"};
constexpr const char* kSensor = "mag_5_uc";
// The flight of the aircraft that checks the drawn sizes (random_effects): the pilot flight's
// scenario seed plus this offset, a flight no benchmark flies (they use the seed and the next two).
constexpr unsigned kOtherFlightSeedOffset = 7919;
// An effect another flight shows this many times larger than its drawn rms is drawn again; on
// the benchmark's runs 101-199 the next flight shows an effect at most 15 times the first's.
constexpr double kMaxOtherFlightRatio = 50.0;
constexpr int kRedraws = 20;

template <class T>
const T& pick(const std::vector<T>& v, std::mt19937_64& rng) {
  return v[std::uniform_int_distribution<size_t>(0, v.size() - 1)(rng)];
}

double uniform(double lo, double hi, std::mt19937_64& rng) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

Eigen::Vector3d unit_vector(std::mt19937_64& rng) {
  std::normal_distribution<double> n;
  Eigen::Vector3d v(n(rng), n(rng), n(rng));
  return v.norm() > 1e-6 ? Eigen::Vector3d(v.normalized()) : Eigen::Vector3d(0, 0, 1);
}

double quantile(Eigen::VectorXd v, double q) {
  std::vector<double> x;
  for (Eigen::Index i = 0; i < v.size(); ++i)
    if (std::isfinite(v[i])) x.push_back(v[i]);
  if (x.empty()) return 0.0;
  const auto k = static_cast<size_t>(q * static_cast<double>(x.size() - 1));
  std::nth_element(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(k), x.end());
  return x[k];
}

// The currents that switch (a product of one with a slowly stepping state is the case the
// loop's product screen must not mistake for two currents).
const std::vector<std::string> kSwitchedCurrents = {"cur_com_1", "cur_ac_hi", "cur_tank",
                                                    "cur_flap",  "cur_strb",  "cur_heat"};

// One effect's kind and shape (unit gain); thresholds filled from the pilot flight later. With
// the aircraft's states recorded (Scenario::aircraft_states), one kind more: a switched current
// times a state (a wire whose field a surface, a valve or a temperature scales), drawn from
// another stream after the kind, so that the other kinds' draws stay as they are.
HiddenEffect draw(std::mt19937_64& rng, bool states) {
  HiddenEffect e;
  const size_t kinds = kKinds.size() + (states ? 1 : 0);
  const size_t kind = std::uniform_int_distribution<size_t>(0, kinds - 1)(rng);
  if (kind == kKinds.size()) {
    e.type = "product";
    e.sensors = {kSensor};
    e.direction = unit_vector(rng);
    e.gain = 1.0;
    e.channel = pick(kSwitchedCurrents, rng);
    e.channel2 = pick(simulated_state_channels(), rng);
    return e;
  }
  e.type = kKinds[kind];
  e.sensors = {kSensor};
  e.direction = unit_vector(rng);
  e.gain = 1.0;
  if (e.type == "wire") {
    e.channel = pick(kCurrents, rng);
    e.position_m = {uniform(-8, 2, rng), uniform(-2, 2, rng), uniform(-1, 1.5, rng)};
    e.length_m = 1.0;
  } else if (e.type == "inductive") {
    e.channel = pick(kCurrents, rng);
  } else if (e.type == "drift") {
    e.channel =
        std::uniform_int_distribution<int>(0, 1)(rng) ? pick(kVoltages, rng) : pick(kCurrents, rng);
    e.time_constant_s = std::exp(uniform(std::log(30.0), std::log(900.0), rng));
  } else if (e.type == "thermal") {
    e.channel = pick(kCurrents, rng);
    e.exponent = std::uniform_int_distribution<int>(0, 1)(rng) ? 2.0 : 1.0;
    e.time_constant_s = std::exp(uniform(std::log(30.0), std::log(600.0), rng));
  } else if (e.type == "relay" || e.type == "hysteresis") {
    e.channel = pick(kCurrents, rng);
  } else if (e.type == "ripple") {
    e.channel = pick(kCurrents, rng);
    e.frequency_hz = uniform(1.2, 4.0, rng);
    e.phase_walk_rad = uniform(0.1, 0.5, rng);
  } else if (e.type == "product") {
    std::vector<std::string> all = kCurrents;
    all.insert(all.end(), kInsChannels.begin(), kInsChannels.end());
    e.channel = pick(all, rng);
    all.insert(all.end(), kVoltages.begin(), kVoltages.end());
    do e.channel2 = pick(all, rng);
    while (e.channel2 == e.channel);
  } else if (e.type == "flex") {
    e.channel = pick(kInsChannels, rng);
    e.time_constant_s = std::uniform_int_distribution<int>(0, 1)(rng) ? 0.0 : uniform(0.5, 5, rng);
  } else if (e.type == "lag") {
    e.lag_s = uniform(0.1, 0.5, rng);
  }
  return e;
}

// How many distinct effects draw() can give: one per (kind, channel), one lag.
int drawable_effects() {
  const int currents = static_cast<int>(kCurrents.size()),
            voltages = static_cast<int>(kVoltages.size()),
            ins = static_cast<int>(kInsChannels.size());
  int n = 0;
  for (const std::string& kind : kKinds) {
    if (kind == "drift") {
      n += currents + voltages;
    } else if (kind == "product") {
      n += currents + ins;  // keyed on its first channel
    } else if (kind == "flex") {
      n += ins;
    } else if (kind == "lag") {
      n += 1;
    } else {
      n += currents;
    }
  }
  return n;
}

double rms_of(const Simulation& s, size_t k, const std::string& type) {
  const std::string col = std::string(kSensor) + ".hidden." + std::to_string(k) + "." + type;
  if (!s.truth.has(col)) return 0.0;
  const Eigen::VectorXd c = s.truth.column(col);
  const double mean = c.mean();
  return std::sqrt((c.array() - mean).square().mean());
}

}  // namespace

std::vector<HiddenEffect> random_effects(const Scenario& base, unsigned seed, int count,
                                         const Igrf& igrf, double rms_min, double rms_max) {
  if (count < 1) throw Error("random effects: the count must be >= 1");
  if (count > drawable_effects())
    throw Error("random effects: --random-count " + std::to_string(count) + " exceeds the " +
                std::to_string(drawable_effects()) +
                " distinct effects that can be drawn (one per kind and channel, one lag)");
  if (!(rms_min > 0 && rms_max >= rms_min)) throw Error("random effects: bad rms range");
  std::mt19937_64 rng(seed * 2654435761ULL + 17);
  std::vector<HiddenEffect> shapes;  // unit gains, no thresholds
  // One lag at most (two would act as one), and no kind twice on one channel.
  const auto taken = [&](const HiddenEffect& x, size_t skip) {
    for (size_t k = 0; k < shapes.size(); ++k)
      if (k != skip && shapes[k].type == x.type &&
          (x.type == "lag" || shapes[k].channel == x.channel))
        return true;
    return false;
  };
  for (int k = 0; k < count; ++k) {
    HiddenEffect e = draw(rng, base.aircraft_states);
    while (taken(e, shapes.size())) e = draw(rng, base.aircraft_states);
    shapes.push_back(e);
  }
  std::vector<double> target;
  for (int k = 0; k < count; ++k)
    target.push_back(std::exp(uniform(std::log(rms_min), std::log(rms_max), rng)));
  const size_t first = base.hidden.size();
  // Pilot: the channels of this flight (the hidden effects do not change them) give the
  // thresholds, then each unit effect's size.
  const auto sized = [&]() {
    std::vector<HiddenEffect> drawn = shapes;
    bool thresholds = false;
    for (const HiddenEffect& e : drawn) thresholds |= e.type == "relay" || e.type == "hysteresis";
    if (thresholds) {
      const Simulation channels = simulate(base, igrf);
      for (HiddenEffect& e : drawn) {
        if (e.type != "relay" && e.type != "hysteresis") continue;
        const Eigen::VectorXd c = channels.flight.column(e.channel);
        e.threshold = e.type == "relay"
                          ? quantile(c, uniform(0.3, 0.7, rng))
                          : uniform(0.1, 0.3, rng) * (quantile(c, 0.95) - quantile(c, 0.05));
        if (e.type == "hysteresis" && !(e.threshold > 0)) e.threshold = 0.1;
      }
    }
    Scenario pilot = base;
    for (const HiddenEffect& e : drawn) pilot.hidden.push_back(e);
    const Simulation unit = simulate(pilot, igrf);
    for (size_t k = 0; k < drawn.size(); ++k) {
      HiddenEffect& e = drawn[k];
      if (e.type == "lag") continue;
      const double r = rms_of(unit, first + k, e.type);
      const double scale = r > 1e-12 ? target[k] / r : 0.0;
      if (e.type == "wire") {
        e.length_m = std::clamp(e.length_m * scale, 1e-3, 100.0);
      } else {
        e.gain *= scale;
      }
    }
    return drawn;
  };
  // A flight that barely shows an effect cannot size it: sized to its drawn rms there, it may be
  // hundreds of times larger on the aircraft's other flights (a product with the flap angle on a
  // pilot flight that never extends the flaps: 0.47 nT rms there, 201 nT on the next flight).
  // Another flight of the aircraft checks each effect; one it shows kMaxOtherFlightRatio times
  // larger than its drawn rms is drawn again (kind and channels), at most kRedraws times in all.
  std::vector<HiddenEffect> drawn = sized();
  for (int redraws = 0;; ++redraws) {
    Scenario other = base;
    other.seed = base.seed + kOtherFlightSeedOffset;
    for (const HiddenEffect& e : drawn) other.hidden.push_back(e);
    const Simulation check = simulate(other, igrf);
    std::vector<size_t> unbounded;
    for (size_t k = 0; k < drawn.size(); ++k)
      if (drawn[k].type != "lag" &&
          !(rms_of(check, first + k, drawn[k].type) <= kMaxOtherFlightRatio * target[k]))
        unbounded.push_back(k);
    if (unbounded.empty()) return drawn;
    if (redraws == kRedraws)
      throw Error("random effects: seed " + std::to_string(seed) + ": " +
                  describe(drawn[unbounded.front()]) + " is still more than " +
                  std::to_string(static_cast<int>(kMaxOtherFlightRatio)) +
                  " times larger on another flight of the aircraft than on the flight that sizes "
                  "it after " +
                  std::to_string(kRedraws) + " draws");
    for (size_t k : unbounded) {
      HiddenEffect e = draw(rng, base.aircraft_states);
      while (taken(e, k)) e = draw(rng, base.aircraft_states);
      shapes[k] = e;
    }
    drawn = sized();
  }
}

bool predictable(const HiddenEffect& e) { return e.type != "ripple"; }

std::string describe(const HiddenEffect& e) {
  std::ostringstream o;
  o.precision(3);
  o << e.type;
  if (!e.channel.empty()) o << " " << e.channel;
  if (!e.channel2.empty()) o << "*" << e.channel2;
  if (e.type == "thermal") o << "^" << e.exponent;
  if (e.type == "drift" || e.type == "thermal" || (e.type == "flex" && e.time_constant_s > 0))
    o << " lp " << e.time_constant_s << " s";
  if (e.type == "relay") o << " > " << e.threshold;
  if (e.type == "hysteresis") o << " play " << e.threshold;
  if (e.type == "ripple") o << " " << e.frequency_hz << " Hz";
  if (e.type == "lag") o << " " << e.lag_s << " s";
  return o.str();
}

}  // namespace magcomp::sim
