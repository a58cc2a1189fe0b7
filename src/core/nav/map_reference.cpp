// magcomp: the map as the reference field (map_reference.h).
#include "magcomp/core/nav/map_reference.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "magcomp/core/error.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/flight_navigation.h"

namespace magcomp::nav {

bool names_map(const std::string& spec, std::string* path) {
  if (spec.rfind("map:", 0) != 0) return false;
  if (path) *path = spec.substr(4);
  return true;
}

MapReference map_reference(const FlightData& f, AnomalyMap map, MapTrack track, const Igrf& igrf,
                           const Eigen::VectorXd* lat_in, const Eigen::VectorXd* lon_in) {
  const Eigen::Index n = f.size();
  Eigen::VectorXd lat_rad(n), lon_rad(n);
  if (track == MapTrack::Given) {
    if (!lat_in || !lon_in || lat_in->size() != n || lon_in->size() != n)
      throw Error("map reference: one given position per row is needed");
    lat_rad = *lat_in;
    lon_rad = *lon_in;
  } else {
    const char* lat_name = track == MapTrack::Truth ? "lat" : "ins_lat";
    const char* lon_name = track == MapTrack::Truth ? "lon" : "ins_lon";
    for (const char* name : {lat_name, lon_name})
      if (!f.has(name))
        throw Error(f.source() + ": field " + name + " (the map's track) not found");
    if (track == MapTrack::Truth) {  // degrees in the flight schema
      lat_rad = Eigen::VectorXd(f.column("lat")) * kDegToRad;
      lon_rad = Eigen::VectorXd(f.column("lon")) * kDegToRad;
    } else if (f.has("lat") && f.has("lon")) {  // radians (MIT) or degrees (MagNav.jl)
      lat_rad = radians_like(f.column("ins_lat"), f.column("lat"));
      lon_rad = radians_like(f.column("ins_lon"), f.column("lon"));
    } else {
      lat_rad = f.column("ins_lat");
      lon_rad = f.column("ins_lon");
      if (lat_rad.cwiseAbs().maxCoeff() > kPi / 2) lat_rad *= kDegToRad, lon_rad *= kDegToRad;
    }
  }
  const Eigen::VectorXd height = flight_height_m(f);
  MapReference out;
  double sum = 0;
  long used = 0;
  for (Eigen::Index i = 0; i < n; ++i)
    if (std::isfinite(height[i])) sum += height[i], ++used;
  out.flight_altitude_m = used ? sum / static_cast<double>(used) : NAN;
  if (std::isfinite(out.flight_altitude_m) && out.flight_altitude_m > map.alt_m + 1.0) {
    map = continued_to(map, out.flight_altitude_m);
  } else if (std::isfinite(out.flight_altitude_m) && out.flight_altitude_m < map.alt_m - 1.0) {
    char buf[200];
    std::snprintf(buf, sizeof buf,
                  "the map lies %.0f m above the flight's mean height (%.0f m above the "
                  "ellipsoid): it is used as it is (no downward continuation), its anomaly "
                  "weaker than the flight's",
                  map.alt_m - out.flight_altitude_m, out.flight_altitude_m);
    out.notes.push_back(buf);
  }
  out.map_altitude_m = map.alt_m;
  const bool dated = f.has("year") && f.has("doy");
  const Eigen::VectorXd year = dated ? Eigen::VectorXd(f.column("year")) : Eigen::VectorXd();
  const Eigen::VectorXd doy = dated ? Eigen::VectorXd(f.column("doy")) : Eigen::VectorXd();
  const Eigen::VectorXd diurnal =
      f.has("diurnal") ? Eigen::VectorXd(f.column("diurnal")) : Eigen::VectorXd::Zero(n);
  if (!dated) throw Error(f.source() + ": fields year and doy (the IGRF's date) not found");
  const Eigen::VectorXd tt = f.tt();
  // The main field every kIgrfStride rows (and at the last), linear in between: it changes by
  // hundredths of a nT over a second of flight.
  constexpr Eigen::Index kIgrfStride = 10;
  const auto igrf_at = [&](Eigen::Index i) -> double {
    if (!std::isfinite(lat_rad[i]) || !std::isfinite(lon_rad[i]) || !std::isfinite(height[i]) ||
        !std::isfinite(year[i]) || !std::isfinite(doy[i]))
      return NAN;
    const double y = decimal_year(static_cast<int>(year[i]), doy[i], tt[i]);
    return igrf.geodetic(lat_rad[i] * kRadToDeg, lon_rad[i] * kRadToDeg, height[i], y).total_nT();
  };
  Eigen::VectorXd main_nT(n);
  for (Eigen::Index a = 0; a < n; a += kIgrfStride) {
    const Eigen::Index b = std::min(a + kIgrfStride, n - 1);
    const double fa = igrf_at(a), fb = b > a ? igrf_at(b) : fa;
    for (Eigen::Index i = a; i < std::min(a + kIgrfStride, n); ++i) {
      const double w = b > a ? static_cast<double>(i - a) / static_cast<double>(b - a) : 0.0;
      main_nT[i] = std::isfinite(fa) && std::isfinite(fb) ? (1 - w) * fa + w * fb : igrf_at(i);
    }
  }
  out.field_nT = Eigen::VectorXd::Constant(n, NAN);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double la = lat_rad[i], lo = lon_rad[i];
    if (!std::isfinite(la) || !std::isfinite(lo) || !std::isfinite(main_nT[i]) ||
        !map.covers(la, lo)) {
      ++out.off_map;
      continue;
    }
    out.field_nT[i] =
        map.value(la, lo) + main_nT[i] + (std::isfinite(diurnal[i]) ? diurnal[i] : 0.0);
  }
  if (out.off_map == n)
    throw Error(f.source() + ": the map covers none of the flight's positions: no reference");
  return out;
}

}  // namespace magcomp::nav
