// magcomp: tracks and measured anomaly of a recorded flight (flight_navigation.h).
#include "magcomp/core/nav/flight_navigation.h"

#include <cmath>
#include <vector>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/error.h"
#include "magcomp/core/geo/anomaly.h"
#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/geo/igrf_track.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/streaming_navigator.h"

namespace magcomp::nav {
namespace {

// The first of `names` the flight has.
Eigen::VectorXd column(const FlightData& f, const std::vector<std::string>& names,
                       const std::string& what) {
  for (const auto& n : names)
    if (f.has(n)) return f.column(n);
  std::string list;
  for (const auto& n : names) list += (list.empty() ? "" : " or ") + n;
  throw Error(f.source() + ": field " + list + " (" + what + ") not found");
}

}  // namespace

bool in_degrees(const Eigen::VectorXd& v, const Eigen::VectorXd& reference_deg) {
  return std::abs(v.mean() - reference_deg.mean()) < 1.0;
}

Eigen::VectorXd radians_like(const Eigen::VectorXd& v, const Eigen::VectorXd& reference_deg) {
  return in_degrees(v, reference_deg) ? Eigen::VectorXd(v * kDegToRad) : v;
}

Eigen::VectorXd flight_height_m(const FlightData& f) {
  // utm_z: GPS height above the ellipsoid (the maps' and the IGRF's datum); msl (older: alt)
  // only without it.
  return column(f, {"utm_z", "msl"}, "true height above the ellipsoid, m");
}

FlightTracks flight_tracks(const FlightData& f) {
  const double dt = f.dt_s();
  const Eigen::VectorXd lat_deg = column(f, {"lat"}, "true latitude, deg");
  const Eigen::VectorXd lon_deg = column(f, {"lon"}, "true longitude, deg");
  const Eigen::VectorXd alt = flight_height_m(f);
  FlightTracks t;
  t.truth = track_from_positions(dt, lat_deg * kDegToRad, lon_deg * kDegToRad, alt,
                                 column(f, {"roll", "ins_roll"}, "roll, deg") * kDegToRad,
                                 column(f, {"pitch", "ins_pitch"}, "pitch, deg") * kDegToRad,
                                 column(f, {"yaw", "ins_yaw"}, "yaw, deg") * kDegToRad);
  t.ins = track_from_positions(dt, radians_like(column(f, {"ins_lat"}, "INS latitude"), lat_deg),
                               radians_like(column(f, {"ins_lon"}, "INS longitude"), lon_deg),
                               column(f, {"ins_alt"}, "INS altitude, m"),
                               column(f, {"ins_roll"}, "INS roll, deg") * kDegToRad,
                               column(f, {"ins_pitch"}, "INS pitch, deg") * kDegToRad,
                               column(f, {"ins_yaw"}, "INS yaw, deg") * kDegToRad);
  t.mean_alt_m = alt.mean();
  return t;
}

FlightSamples flight_samples(const FlightData& f) {
  const Eigen::VectorXd lat_deg = column(f, {"lat"}, "true latitude, deg");
  const Eigen::VectorXd lon_deg = column(f, {"lon"}, "true longitude, deg");
  const Eigen::VectorXd alt = flight_height_m(f);
  const Eigen::VectorXd roll = column(f, {"roll", "ins_roll"}, "roll, deg") * kDegToRad;
  const Eigen::VectorXd pitch = column(f, {"pitch", "ins_pitch"}, "pitch, deg") * kDegToRad;
  const Eigen::VectorXd yaw = column(f, {"yaw", "ins_yaw"}, "yaw, deg") * kDegToRad;
  // The INS angles' unit (rad or deg) judged on the rows where both columns are finite.
  const auto radians = [&](const Eigen::VectorXd& v, const Eigen::VectorXd& ref_deg) {
    double sv = 0, sr = 0;
    long n = 0;
    for (Eigen::Index i = 0; i < v.size(); ++i)
      if (std::isfinite(v[i]) && std::isfinite(ref_deg[i])) sv += v[i], sr += ref_deg[i], ++n;
    return n > 0 && std::abs(sv / n - sr / n) < 1.0 ? Eigen::VectorXd(v * kDegToRad) : v;
  };
  const Eigen::VectorXd ins_lat = radians(column(f, {"ins_lat"}, "INS latitude"), lat_deg);
  const Eigen::VectorXd ins_lon = radians(column(f, {"ins_lon"}, "INS longitude"), lon_deg);
  const Eigen::VectorXd ins_alt = column(f, {"ins_alt"}, "INS altitude, m");
  const Eigen::VectorXd ins_roll = column(f, {"ins_roll"}, "INS roll, deg") * kDegToRad;
  const Eigen::VectorXd ins_pitch = column(f, {"ins_pitch"}, "INS pitch, deg") * kDegToRad;
  const Eigen::VectorXd ins_yaw = column(f, {"ins_yaw"}, "INS yaw, deg") * kDegToRad;
  const Eigen::VectorXd tt = f.tt();
  FlightSamples s;
  s.dt_s = f.dt_s();
  s.ins.resize(static_cast<size_t>(f.size()));
  s.truth.resize(static_cast<size_t>(f.size()));
  double alt_sum = 0;
  long alt_n = 0;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    s.ins[static_cast<size_t>(i)] = {tt[i],       ins_lat[i],   ins_lon[i], ins_alt[i],
                                     ins_roll[i], ins_pitch[i], ins_yaw[i]};
    const InsSample t{
        tt[i], lat_deg[i] * kDegToRad, lon_deg[i] * kDegToRad, alt[i], roll[i], pitch[i], yaw[i]};
    s.truth[static_cast<size_t>(i)] = t;
    if (invalid_ins_reason(t).empty()) alt_sum += alt[i], ++alt_n;
  }
  if (alt_n > 0) s.mean_alt_m = alt_sum / static_cast<double>(alt_n);
  return s;
}

Eigen::VectorXd measured_anomaly_nT(const FlightData& f, const Model& m, bool uncompensated) {
  require_model_fields_in_range(m, f);
  const Eigen::VectorXd total =
      uncompensated ? column(f, {m.scalar}, "the model's scalar") : compensate(m, f);
  return flight_anomaly_nT(f, total);
}

Eigen::VectorXd flight_anomaly_nT(const FlightData& f, const Eigen::VectorXd& total_nT) {
  return anomaly_nT(total_nT, igrf_total_nT(f, Igrf::installed()),
                    f.has("diurnal") ? Eigen::VectorXd(f.column("diurnal")) : Eigen::VectorXd());
}

}  // namespace magcomp::nav
