// magcomp simulator: a scenario = flight plan + Earth field + aircraft + sensors + hidden effects.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

namespace magcomp::sim {

/// One piece of the flight plan. Turns and climbs between segments are inserted automatically.
struct Segment {
  std::string type;          ///< box | cloverleaf | line | grid | figure8
  double line = 0.0;         ///< line number (grid: the first line; +0.01 per further line)
  double heading_deg = 0.0;  ///< clockwise from north
  double duration_s = 0.0;   ///< line, figure8: total; box/cloverleaf: per leg; grid: per line
  double altitude_m = 0.0;   ///< above the WGS-84 ellipsoid; 0 keeps the current altitude
  int lines = 1;             ///< grid only
};

/// A hidden (or visible) physical effect the simulator adds to the scalar sensors.
struct HiddenEffect {
  /// wire | inductive | lag | fluxgate | heading | drift | thermal | eddy_decay | flex | relay |
  /// ripple | product | hysteresis | saturation
  std::string type;
  std::string channel;  ///< wire / inductive / drift: the current or other channel
  std::string
      channel2;  ///< product: the second channel (b = gain · direction · channel · channel2)
  Eigen::Vector3d position_m{0, 0, 0};  ///< wire: midpoint in base_link (x fwd, y left, z up)
  Eigen::Vector3d direction{1, 0, 0};   ///< wire: along the wire; inductive/heading: field axis
  double length_m = 1.0;                ///< wire length
  /// inductive: nT per A/s at 1 m scale; heading: nT; drift, flex: nT per unit of the channel;
  /// thermal: nT per unit of lp(|I|^exponent); eddy_decay: s (scale of its 3x3 eddy matrix);
  /// relay: nT while the channel is above the threshold; ripple: nT per unit of the channel
  double gain = 0.0;
  double lag_s = 0.0;  ///< lag: scalar sensors read the field lag_s late
  /// drift, thermal: low-pass of the channel; eddy_decay: decay of the eddy currents; flex: the
  /// structure's response (0: none)
  double time_constant_s = 300.0;
  double exponent = 2.0;   ///< thermal: heating ∝ |I|^exponent (2: Joule heating)
  double threshold = 0.0;  ///< relay: the channel value above which the device is on;
                           ///< hysteresis: the play half-width (channel units);
                           ///< saturation: the dead band's end (channel units)
  /// saturation: where the core saturates, in channel units above the dead band: b = gain ·
  /// direction · level · tanh(max(x - threshold, 0) / level) (a law no closed form of the term
  /// language writes)
  double level = 1.0;
  /// ripple: a sine on the scalar of amplitude gain x channel at frequency_hz, whose phase walks
  /// at random by phase_walk_rad per sqrt(s) and is recorded by no channel
  double frequency_hz = 2.0;
  double phase_walk_rad = 0.3;
  Eigen::Vector3d scale{0, 0, 0};                 ///< fluxgate: scale errors (fraction) per axis
  Eigen::Vector3d nonorthogonality_rad{0, 0, 0};  ///< fluxgate: xy, xz, yz angles
  Eigen::Vector3d offset_nT{0, 0, 0};             ///< fluxgate: offsets
  std::vector<std::string> sensors;  ///< sensors affected (empty: every scalar / every fluxgate)
};

/// Everything a simulated flight is made of. Units in the names; SI + nT.
struct Scenario {
  std::string source = "<memory>";
  unsigned seed = 1;
  double flight = 1001.0;
  int year = 2020;
  int doy = 181;
  double start_tt_s = 36000.0;
  double origin_lat_deg = 45.3;
  double origin_lon_deg = -75.7;
  double speed_mps = 60.0;
  double turn_bank_deg = 25.0;
  double climb_rate_mps = 5.0;
  double sample_rate_hz = 10.0;
  double start_altitude_m = 1000.0;
  std::vector<Segment> segments;
  // Earth
  double anomaly_rms_nT = 150.0;        ///< crustal anomaly rms at the ground (before continuation)
  double anomaly_spectral_slope = 3.0;  ///< power spectrum ∝ k^-slope
  double anomaly_grid_m = 100.0;
  int anomaly_grid_n = 512;
  double terrain_m = 80.0;  ///< ground height above the ellipsoid
  double diurnal_amplitude_nT = 15.0;
  // Aircraft and sensors
  double aircraft_scale = 1.0;   ///< multiplies every aircraft-field coefficient
  long long aircraft_seed = -1;  ///< draws the aircraft field (same value: same aircraft across
                                 ///< flights); -1: from the flight's own random stream
  double turbulence_deg = 0.3;   ///< rms attitude turbulence
  /// Record the aircraft's non-electrical states too (simulated_state_channels(): flap setting,
  /// engine speed, outside air temperature, a heater switch; YAML aircraft.states). Drawn from
  /// their own random stream: every other channel and field of the flight is unchanged.
  bool aircraft_states = false;
  double scalar_noise_nT = 0.005;  ///< cesium white noise rms
  double fluxgate_noise_nT = 0.3;  ///< fluxgate white noise rms per axis
  std::vector<HiddenEffect> hidden;
  // Navigation (optional `navigation:` section; without it the flight is unchanged)
  bool nav_map = false;              ///< write the anomaly map beside the flight (F.map.h5)
  double nav_map_margin_m = 3000.0;  ///< map extent beyond the flight's, m
  bool nav_ins_drift = false;        ///< ins_lat/ins_lon/ins_alt drift as a navigation-grade INS
  unsigned nav_ins_seed = 1;         ///< the drift's own random stream
};

/// Loads and validates a scenario YAML. Throws magcomp::Error naming the file and key for an
/// unknown key, a wrong type, a negative noise, an unknown effect type or channel.
Scenario load_scenario(const std::string& path);

/// The electrical channels the simulator produces (currents cur_*, voltages vol_*).
const std::vector<std::string>& simulated_channels();

/// The non-electrical state channels it adds with Scenario::aircraft_states: flap_deg (the flap
/// setting, 0/10/20 deg), eng_rpm (engine speed), oat_degC (outside air temperature, with the
/// altitude) and sw_pitot_heat (the pitot heater's switch, 0/1).
const std::vector<std::string>& simulated_state_channels();

/// The scalar and vector sensors and their positions in base_link (m), DATA.md.
struct SensorMount {
  std::string name;  ///< mag_1_uc ... / flux_a ...
  bool vector = false;
  Eigen::Vector3d position_m;
  double aircraft_weight = 1.0;  ///< relative size of the aircraft field there
};
const std::vector<SensorMount>& sensor_mounts();

}  // namespace magcomp::sim
