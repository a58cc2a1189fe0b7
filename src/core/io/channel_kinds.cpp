// magcomp: the kinds of recorded channels, by name (channel_kinds.h).
#include "magcomp/core/io/channel_kinds.h"

#include <set>

namespace magcomp {
namespace {

bool ends_with(const std::string& n, const std::string& tail) {
  return n.size() > tail.size() && n.compare(n.size() - tail.size(), tail.size(), tail) == 0;
}

}  // namespace

bool is_electrical(const std::string& channel) {
  return channel.rfind("cur_", 0) == 0 || channel.rfind("vol_", 0) == 0;
}

bool is_bookkeeping_channel(const std::string& channel) {
  static const std::set<std::string> kBookkeeping = {"tt",  "line", "flight", "year",
                                                     "doy", "N",    "dt"};
  return kBookkeeping.count(channel) > 0;
}

bool is_motion_channel(const std::string& n) {
  static const std::set<std::string> kNamed = {"vn",      "ve",      "vw",       "vu",      "vd",
                                               "pitch",   "roll",    "yaw",      "heading", "tas",
                                               "true_as", "pitot_p", "static_p", "total_p"};
  return n.rfind("ins_", 0) == 0 || ends_with(n, "_rate") || ends_with(n, "_rt") ||
         ends_with(n, "_acc") || kNamed.count(n) > 0;
}

bool is_position_channel(const std::string& name) {
  static const std::set<std::string> kPosition = {
      "lat",     "lon",     "utm_x", "utm_y", "utm_z", "utmX",  "utmY", "utmZ", "ins_lat",
      "ins_lon", "ins_alt", "msl",   "alt",   "baro",  "radar", "topo", "dem",  "drape"};
  return kPosition.count(name) > 0;
}

bool is_earth_frame_velocity(const std::string& name) {
  static const std::set<std::string> kVelocity = {"ins_vn", "ins_ve", "ins_vw", "ins_vu", "ins_vd",
                                                  "vn",     "ve",     "vw",     "vu",     "vd"};
  return kVelocity.count(name) > 0;
}

bool is_aircraft_state(const std::string& n) {
  if (n.empty()) return false;
  if (is_electrical(n)) return true;
  return !is_motion_channel(n) && !is_position_channel(n) && !is_bookkeeping_channel(n) &&
         n.rfind("mag_", 0) != 0 && n.rfind("flux_", 0) != 0 && n.rfind("ogs_", 0) != 0 &&
         n != "diurnal" && n.front() != '~';
}

}  // namespace magcomp
