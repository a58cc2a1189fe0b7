// magcomp: what a recorded channel is, read from its name: an electrical source, motion or air
// data, a position or the trajectory, a state of the aircraft. Diagnose and the network's
// attribution both sort channels by these kinds.
#pragma once

#include <string>

namespace magcomp {

/// Whether a channel is one of the aircraft's electrical sources (cur_*, vol_*): written with the
/// current: shorthand.
bool is_electrical(const std::string& channel);

/// Whether a channel is bookkeeping: tt, line, flight, year, doy, N, dt.
bool is_bookkeeping_channel(const std::string& channel);

/// Whether a channel is motion or air data: the INS's (ins_*), an angular rate (*_rate, *_rt),
/// an acceleration (*_acc), a velocity (vn, ve, vw, vu, vd), the attitude (pitch, roll, yaw,
/// heading), the airspeed and the air pressures (tas, true_as, pitot_p, static_p, total_p).
bool is_motion_channel(const std::string& channel);

/// The position and trajectory channels (lat, lon, utm_*, ins_lat, ins_lon, heights): no source of
/// aircraft field. A residual that follows them is map or trajectory leakage (the reference fit,
/// IGRF or diurnal), never a term.
bool is_position_channel(const std::string& name);

/// The earth-frame velocities (ins_vn, ins_vw, ins_vu, vn, ve, ...), m/s: the trajectory's heading
/// and climb. A term of one alone can stand for a slow heading-dependent error, but a product of
/// one with another channel is no aircraft source: the product screen passes them over.
bool is_earth_frame_velocity(const std::string& name);

/// Whether a channel is a recorded state of the aircraft: a current or a voltage, or any other
/// recorded channel that is not motion or air data (is_motion_channel), a position
/// (is_position_channel), a magnetometer, a fluxgate, the diurnal or map reference or
/// bookkeeping -- a surface or valve position, a temperature, an engine speed, a switch. These
/// are the channels a slow term, a grown chain or a learned law may follow (a slow term or law
/// of motion or position would be leakage of the map or the trajectory).
bool is_aircraft_state(const std::string& channel);

}  // namespace magcomp
