// magcomp simulator: scenario YAML loading with strict validation.
#include "magcomp/core/sim/scenario.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <type_traits>

#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"

namespace magcomp::sim {

const std::vector<std::string>& simulated_channels() {
  static const std::vector<std::string> kChannels = {
      "cur_com_1",  "cur_ac_hi",  "cur_ac_lo",  "cur_tank",   "cur_flap",   "cur_strb",
      "cur_srvo_o", "cur_srvo_m", "cur_srvo_i", "cur_heat",   "cur_acpwr",  "cur_outpwr",
      "cur_bat_1",  "cur_bat_2",  "vol_acpwr",  "vol_outpwr", "vol_bat_1",  "vol_bat_2",
      "vol_res_p",  "vol_res_n",  "vol_back_p", "vol_back_n", "vol_gyro_1", "vol_gyro_2",
      "vol_acc_p",  "vol_acc_n",  "vol_block",  "vol_back",   "vol_srvo",   "vol_cabt",
      "vol_fan"};
  return kChannels;
}

const std::vector<std::string>& simulated_state_channels() {
  static const std::vector<std::string> kStates = {"flap_deg", "eng_rpm", "oat_degC",
                                                   "sw_pitot_heat"};
  return kStates;
}

const std::vector<SensorMount>& sensor_mounts() {
  // DATA.md positions (m from the front seat rail, x forward, y left, z up). flux_a is not given
  // there; the simulator assumes it beside mag 4 on the cabin floor.
  static const std::vector<SensorMount> kMounts = {
      {"mag_1_uc", false, {-12.01, 0.0, 1.37}, 0.01}, {"mag_2_uc", false, {-0.60, -0.36, 0.0}, 1.6},
      {"mag_3_uc", false, {-1.28, -0.36, 0.0}, 1.3},  {"mag_4_uc", false, {-3.53, 0.0, 0.0}, 0.8},
      {"mag_5_uc", false, {-3.79, 0.0, 1.20}, 1.0},   {"flux_a", true, {-3.40, 0.30, 0.0}, 0.06},
      {"flux_b", true, {-8.92, 0.0, 0.96}, 0.02},     {"flux_c", true, {-4.06, 0.42, 0.0}, 0.05},
      {"flux_d", true, {-4.06, -0.42, 0.0}, 0.05}};
  return kMounts;
}

namespace {

struct Reader {
  std::string path;

  void check_keys(const YAML::Node& node, const std::set<std::string>& known,
                  const std::string& where) const {
    if (!node.IsMap()) throw Error(path + ": key '" + where + "' must be a map");
    std::set<std::string> seen;
    for (const auto& kv : node) {
      const std::string key = kv.first.as<std::string>();
      if (!seen.insert(key).second) {
        throw Error(path + ": key '" + (where.empty() ? "" : where + ".") + key + "' given twice");
      }
      if (!known.count(key)) {
        throw Error(path + ": unknown key '" + (where.empty() ? "" : where + ".") + key + "'");
      }
    }
  }
  template <typename T>
  void get(const YAML::Node& node, const std::string& key, const std::string& where, T* out) const {
    if (!node[key]) return;
    const std::string name = (where.empty() ? "" : where + ".") + key;
    try {
      *out = node[key].as<T>();
    } catch (const YAML::Exception&) {
      throw Error(path + ": key '" + name + "' has the wrong type");
    }
    // Every number of a scenario is finite: a range check alone lets NaN through.
    if constexpr (std::is_floating_point_v<T>) {
      if (!std::isfinite(*out)) throw Error(path + ": key '" + name + "' must be finite");
    } else if constexpr (std::is_same_v<T, std::vector<double>>) {
      for (double v : *out) {
        if (!std::isfinite(v)) throw Error(path + ": key '" + name + "' must hold finite numbers");
      }
    }
  }
  void range(double v, double lo, double hi, const std::string& key) const {
    if (!(v >= lo && v <= hi)) {
      throw Error(path + ": key '" + key + "' must be in [" + format(lo) + ", " + format(hi) +
                  "], got " + format(v));
    }
  }
  static std::string format(double v) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%g", v);
    return buf;
  }
  void vec3(const YAML::Node& node, const std::string& key, const std::string& where,
            Eigen::Vector3d* out) const {
    if (!node[key]) return;
    std::vector<double> v;
    get(node, key, where, &v);
    if (v.size() != 3) {
      throw Error(path + ": key '" + where + "." + key + "' must be a list of 3 numbers");
    }
    *out = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  void non_negative(double v, const std::string& key) const {
    if (!(v >= 0)) throw Error(path + ": key '" + key + "' must be >= 0");
  }
  void positive(double v, const std::string& key) const {
    if (!(v > 0)) throw Error(path + ": key '" + key + "' must be > 0");
  }
};

}  // namespace

namespace {

// The earth and sensors sections.
void read_earth_and_sensors(const Reader& r, const YAML::Node& root, Scenario* out) {
  Scenario& s = *out;
  const std::string& path = r.path;
  if (const YAML::Node e = root["earth"]) {
    r.check_keys(e,
                 {"anomaly_rms_nT", "anomaly_spectral_slope", "anomaly_grid_m", "anomaly_grid_n",
                  "terrain_m", "diurnal_amplitude_nT"},
                 "earth");
    r.get(e, "anomaly_rms_nT", "earth", &s.anomaly_rms_nT);
    r.get(e, "anomaly_spectral_slope", "earth", &s.anomaly_spectral_slope);
    r.get(e, "anomaly_grid_m", "earth", &s.anomaly_grid_m);
    r.get(e, "anomaly_grid_n", "earth", &s.anomaly_grid_n);
    r.get(e, "terrain_m", "earth", &s.terrain_m);
    r.get(e, "diurnal_amplitude_nT", "earth", &s.diurnal_amplitude_nT);
    r.range(s.anomaly_rms_nT, 0, 1e5, "earth.anomaly_rms_nT");
    r.range(s.anomaly_spectral_slope, 0, 10, "earth.anomaly_spectral_slope");
    r.range(s.anomaly_grid_m, 1, 1e5, "earth.anomaly_grid_m");
    r.range(s.terrain_m, -500, 9000, "earth.terrain_m");
    r.range(s.diurnal_amplitude_nT, 0, 1e4, "earth.diurnal_amplitude_nT");
    if (s.anomaly_grid_n < 16 || s.anomaly_grid_n > 4096 ||
        (s.anomaly_grid_n & (s.anomaly_grid_n - 1)) != 0) {
      throw Error(path + ": key 'earth.anomaly_grid_n' must be a power of two in 16..4096");
    }
  }
  if (const YAML::Node n = root["sensors"]) {
    r.check_keys(n, {"scalar_noise_nT", "fluxgate_noise_nT", "sample_rate_hz"}, "sensors");
    r.get(n, "scalar_noise_nT", "sensors", &s.scalar_noise_nT);
    r.get(n, "fluxgate_noise_nT", "sensors", &s.fluxgate_noise_nT);
    r.get(n, "sample_rate_hz", "sensors", &s.sample_rate_hz);
    r.range(s.scalar_noise_nT, 0, 1e4, "sensors.scalar_noise_nT");
    r.range(s.fluxgate_noise_nT, 0, 1e4, "sensors.fluxgate_noise_nT");
    r.range(s.sample_rate_hz, 0.1, 1000, "sensors.sample_rate_hz");
  }
}

// The scalar keys and the date, origin and aircraft sections.
void read_settings(const Reader& r, const YAML::Node& root, Scenario* out) {
  Scenario& s = *out;
  const std::string& path = r.path;
  r.check_keys(root,
               {"description", "seed", "flight", "date", "start_tt_s", "origin", "aircraft",
                "earth", "sensors", "start_altitude_m", "plan", "hidden", "navigation"},
               "");
  r.get(root, "seed", "", &s.seed);
  r.get(root, "flight", "", &s.flight);
  r.get(root, "start_tt_s", "", &s.start_tt_s);
  r.get(root, "start_altitude_m", "", &s.start_altitude_m);
  r.range(s.start_tt_s, 0, 86400, "start_tt_s");
  r.range(s.start_altitude_m, 0, 20000, "start_altitude_m");
  if (const YAML::Node n = root["navigation"]) {
    r.check_keys(n, {"map", "map_margin_m", "ins_drift", "ins_seed"}, "navigation");
    r.get(n, "map", "navigation", &s.nav_map);
    r.get(n, "map_margin_m", "navigation", &s.nav_map_margin_m);
    r.get(n, "ins_drift", "navigation", &s.nav_ins_drift);
    r.get(n, "ins_seed", "navigation", &s.nav_ins_seed);
    r.range(s.nav_map_margin_m, 0, 1e6, "navigation.map_margin_m");
  }
  if (root["date"]) {
    r.check_keys(root["date"], {"year", "doy"}, "date");
    r.get(root["date"], "year", "date", &s.year);
    r.get(root["date"], "doy", "date", &s.doy);
    if (s.doy < 1 || s.doy > 366) throw Error(path + ": key 'date.doy' must be in 1..366");
  }
  if (root["origin"]) {
    r.check_keys(root["origin"], {"lat_deg", "lon_deg"}, "origin");
    r.get(root["origin"], "lat_deg", "origin", &s.origin_lat_deg);
    r.get(root["origin"], "lon_deg", "origin", &s.origin_lon_deg);
    if (std::abs(s.origin_lat_deg) > 80)
      throw Error(path + ": key 'origin.lat_deg' must be within +-80");
    r.range(s.origin_lon_deg, -360, 360, "origin.lon_deg");
  }
  if (const YAML::Node a = root["aircraft"]) {
    r.check_keys(a,
                 {"speed_mps", "turn_bank_deg", "climb_rate_mps", "field_scale", "turbulence_deg",
                  "seed", "states"},
                 "aircraft");
    r.get(a, "states", "aircraft", &s.aircraft_states);
    r.get(a, "speed_mps", "aircraft", &s.speed_mps);
    r.get(a, "turn_bank_deg", "aircraft", &s.turn_bank_deg);
    r.get(a, "climb_rate_mps", "aircraft", &s.climb_rate_mps);
    r.get(a, "field_scale", "aircraft", &s.aircraft_scale);
    r.get(a, "turbulence_deg", "aircraft", &s.turbulence_deg);
    r.get(a, "seed", "aircraft", &s.aircraft_seed);
    r.range(s.speed_mps, 1, 400, "aircraft.speed_mps");
    r.range(s.turn_bank_deg, 1, 60, "aircraft.turn_bank_deg");
    r.range(s.climb_rate_mps, 0.1, 50, "aircraft.climb_rate_mps");
    r.range(s.aircraft_scale, 0, 1000, "aircraft.field_scale");
    r.range(s.turbulence_deg, 0, 20, "aircraft.turbulence_deg");
  }
}

// The flight plan, and its length bounded before anything is allocated.
void read_plan(const Reader& r, const YAML::Node& root, Scenario* out) {
  Scenario& s = *out;
  const std::string& path = r.path;
  if (!root["plan"] || !root["plan"].IsSequence() || root["plan"].size() == 0) {
    throw Error(path + ": key 'plan' must be a non-empty list of segments");
  }
  for (size_t i = 0; i < root["plan"].size(); ++i) {
    const YAML::Node p = root["plan"][i];
    const std::string where = "plan[" + std::to_string(i) + "]";
    r.check_keys(p, {"type", "line", "heading_deg", "duration_s", "altitude_m", "lines"}, where);
    Segment g;
    r.get(p, "type", where, &g.type);
    r.get(p, "line", where, &g.line);
    r.get(p, "heading_deg", where, &g.heading_deg);
    r.get(p, "duration_s", where, &g.duration_s);
    r.get(p, "altitude_m", where, &g.altitude_m);
    r.get(p, "lines", where, &g.lines);
    static const std::set<std::string> kTypes = {"box", "cloverleaf", "line", "grid", "figure8"};
    if (!kTypes.count(g.type)) {
      throw Error(path + ": key '" + where +
                  ".type' must be box, cloverleaf, line, grid or figure8");
    }
    r.range(g.duration_s, 1e-3, 86400, where + ".duration_s");
    r.range(g.altitude_m, 0, 20000, where + ".altitude_m");
    r.range(g.heading_deg, -360, 360, where + ".heading_deg");
    if (g.lines < 1 || g.lines > 1000)
      throw Error(path + ": key '" + where + ".lines' must be in 1..1000");
    s.segments.push_back(g);
  }
  // The flight's length, before anything is allocated: segments (box and cloverleaf fly four
  // legs, a grid `lines` lines) plus a generous allowance for the turns and climbs between them.
  double seconds = 0;
  for (const Segment& g : s.segments) {
    const double legs = g.type == "box" || g.type == "cloverleaf" ? 4
                        : g.type == "grid"                        ? g.lines
                                                                  : 1;
    seconds += g.duration_s * legs + 600.0;
  }
  constexpr double kMaxSamples = 5e6;  // ~140 h at 10 Hz: every field of it is ~4 GB
  if (seconds * s.sample_rate_hz > kMaxSamples) {
    throw Error(path + ": key 'plan' makes about " + Reader::format(seconds * s.sample_rate_hz) +
                " samples; at most " + Reader::format(kMaxSamples) + " are simulated");
  }
}

// One hidden effect, checked against the simulated channels and sensors.
HiddenEffect read_hidden_effect(const Reader& r, const YAML::Node& e, const std::string& where,
                                const std::set<std::string>& channels,
                                const std::set<std::string>& sensors) {
  const std::string& path = r.path;
  r.check_keys(e,
               {"type", "channel", "position_m", "direction", "length_m", "gain", "lag_s",
                "time_constant_s", "scale", "nonorthogonality_rad", "offset_nT", "sensors",
                "exponent", "threshold", "level", "frequency_hz", "phase_walk_rad", "channel2"},
               where);
  HiddenEffect x;
  r.get(e, "type", where, &x.type);
  r.get(e, "channel", where, &x.channel);
  r.get(e, "channel2", where, &x.channel2);
  r.vec3(e, "position_m", where, &x.position_m);
  r.vec3(e, "direction", where, &x.direction);
  r.get(e, "length_m", where, &x.length_m);
  r.get(e, "gain", where, &x.gain);
  r.get(e, "lag_s", where, &x.lag_s);
  r.get(e, "time_constant_s", where, &x.time_constant_s);
  r.vec3(e, "scale", where, &x.scale);
  r.vec3(e, "nonorthogonality_rad", where, &x.nonorthogonality_rad);
  r.vec3(e, "offset_nT", where, &x.offset_nT);
  r.get(e, "sensors", where, &x.sensors);
  r.get(e, "exponent", where, &x.exponent);
  r.get(e, "threshold", where, &x.threshold);
  r.get(e, "level", where, &x.level);
  r.get(e, "frequency_hz", where, &x.frequency_hz);
  r.get(e, "phase_walk_rad", where, &x.phase_walk_rad);
  static const std::set<std::string> kTypes = {
      "wire", "inductive",  "lag",   "fluxgate", "heading", "drift",      "thermal",
      "flex", "eddy_decay", "relay", "ripple",   "product", "hysteresis", "saturation"};
  if (!kTypes.count(x.type)) {
    throw Error(path + ": key '" + where +
                ".type' must be wire, inductive, lag, fluxgate, heading, drift, thermal, "
                "eddy_decay, flex, relay, ripple, product, hysteresis or saturation");
  }
  if (x.type == "flex" && x.channel.empty()) x.channel = "nrml_acc";
  if (x.type == "flex" && !e["time_constant_s"]) x.time_constant_s = 0.0;
  const bool needs_channel = x.type == "wire" || x.type == "inductive" || x.type == "drift" ||
                             x.type == "thermal" || x.type == "relay" || x.type == "ripple" ||
                             x.type == "hysteresis" || x.type == "saturation";
  if (needs_channel && !channels.count(x.channel)) {
    throw Error(path + ": key '" + where + ".channel': unknown channel '" + x.channel + "'");
  }
  static const std::set<std::string> kInsChannels = {"nrml_acc",   "lgtl_acc",  "ltrl_acc",
                                                     "ins_acc_x",  "ins_acc_y", "ins_acc_z",
                                                     "pitch_rate", "roll_rate", "yaw_rate"};
  if (x.type == "product") {
    for (const auto& [key, name] :
         {std::make_pair("channel", x.channel), std::make_pair("channel2", x.channel2)}) {
      if (!channels.count(name) && !kInsChannels.count(name))
        throw Error(path + ": key '" + where + "." + key + "': unknown channel '" + name + "'");
    }
  }
  static const std::set<std::string> kFlexChannels = {"nrml_acc",   "lgtl_acc",  "ltrl_acc",
                                                      "ins_acc_x",  "ins_acc_y", "ins_acc_z",
                                                      "pitch_rate", "roll_rate", "yaw_rate"};
  if (x.type == "flex" && !kFlexChannels.count(x.channel)) {
    throw Error(path + ": key '" + where +
                ".channel': flex follows an INS channel (nrml_acc, "
                "ins_acc_*, *_rate), not '" +
                x.channel + "'");
  }
  for (const char* k : {"gain", "lag_s", "time_constant_s", "length_m", "exponent", "threshold",
                        "level", "frequency_hz", "phase_walk_rad"}) {
    if (e[k] && !std::isfinite(e[k].as<double>())) {
      throw Error(path + ": key '" + where + "." + k + "' must be finite");
    }
  }
  if (x.type == "thermal" || x.type == "eddy_decay")
    r.positive(x.time_constant_s, where + ".time_constant_s");
  if (x.type == "flex") r.non_negative(x.time_constant_s, where + ".time_constant_s");
  if (x.type == "thermal" && !(x.exponent > 0 && x.exponent <= 4))
    throw Error(path + ": key '" + where + ".exponent' must be in (0, 4]");
  for (const auto& sensor : x.sensors) {
    if (!sensors.count(sensor)) {
      throw Error(path + ": key '" + where + ".sensors': unknown sensor '" + sensor + "'");
    }
  }
  if (x.type == "saturation") r.positive(x.level, where + ".level");
  if (x.type == "wire") r.range(x.length_m, 1e-3, 100, where + ".length_m");
  if (x.type == "lag") r.range(x.lag_s, 0, 60, where + ".lag_s");
  if (x.type == "ripple") {
    r.range(x.frequency_hz, 1e-3, 1e3, where + ".frequency_hz");
    r.range(x.phase_walk_rad, 0, 100, where + ".phase_walk_rad");
  }
  r.range(x.gain, -1e6, 1e6, where + ".gain");
  if (e["time_constant_s"]) r.range(x.time_constant_s, 0, 1e6, where + ".time_constant_s");
  if (x.type == "drift") r.positive(x.time_constant_s, where + ".time_constant_s");
  if (x.direction.norm() == 0) throw Error(path + ": key '" + where + ".direction' is zero");
  x.direction.normalize();
  return x;
}

// The hidden effects (optional).
void read_hidden(const Reader& r, const YAML::Node& root, Scenario* out) {
  const std::string& path = r.path;
  std::set<std::string> channels(simulated_channels().begin(), simulated_channels().end());
  if (out->aircraft_states)
    channels.insert(simulated_state_channels().begin(), simulated_state_channels().end());
  std::set<std::string> sensors;
  for (const auto& m : sensor_mounts()) sensors.insert(m.name);
  const YAML::Node h = root["hidden"];
  if (!h) return;
  if (!h.IsSequence()) throw Error(path + ": key 'hidden' must be a list of effects");
  for (size_t i = 0; i < h.size(); ++i) {
    out->hidden.push_back(
        read_hidden_effect(r, h[i], "hidden[" + std::to_string(i) + "]", channels, sensors));
  }
}

}  // namespace

static Scenario load_scenario_unchecked(const std::string& path) {
  YAML::Node root;
  require_regular_file(path, "scenario file");
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw Error(path + ": scenario file not found or not readable");
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not valid YAML (line " + std::to_string(e.mark.line + 1) + ")");
  }
  const Reader r{path};
  Scenario s;
  s.source = path;
  read_settings(r, root, &s);
  read_earth_and_sensors(r, root, &s);
  read_plan(r, root, &s);
  read_hidden(r, root, &s);
  return s;
}

Scenario load_scenario(const std::string& path) {
  // A YAML oddity the checks above do not foresee (a key that is a list, say) is still one line
  // naming the file, never an escaping yaml-cpp exception.
  try {
    return load_scenario_unchecked(path);
  } catch (const Error&) {
    throw;
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not a valid scenario (" + e.msg + ", line " +
                std::to_string(e.mark.line + 1) + ")");
  } catch (const std::exception& e) {
    throw Error(path + ": cannot read the scenario (" + e.what() + ")");
  }
}

}  // namespace magcomp::sim
