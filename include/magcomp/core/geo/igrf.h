// magcomp: the International Geomagnetic Reference Field (IGRF-14) from an SHC coefficient file.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/io/time_base.h"  // decimal_year: the date IGRF takes

namespace magcomp {

/// Main-field vector in nT, in a local north-east-down frame.
struct FieldNED {
  double north_nT = 0.0;
  double east_nT = 0.0;
  double down_nT = 0.0;
  double total_nT() const;
};

/// Spherical-harmonic main-field model, Schmidt semi-normalised coefficients interpolated
/// linearly between epochs (the SHC format of the reference implementation).
class Igrf {
 public:
  /// Loads an SHC file. Throws magcomp::Error naming the file and line on bad content.
  static Igrf load(const std::string& shc_path);
  /// The copy installed with magcomp (config/igrf14.shc; MAGCOMP_IGRF_FILE overrides it), read
  /// from the file at each call: load it once where a program starts and pass it on.
  static Igrf installed();

  /// Geocentric field: colatitude and longitude in degrees, radius in km, decimal year.
  /// Returns X north, Y east, Z down (geocentric frame), nT.
  FieldNED geocentric(double colatitude_deg, double longitude_deg, double radius_km,
                      double year) const;
  /// Geodetic field: WGS-84 latitude and longitude in degrees, height above the ellipsoid in m,
  /// decimal year. Returns north, east, down in the local geodetic frame, nT.
  FieldNED geodetic(double latitude_deg, double longitude_deg, double height_m, double year) const;

  double first_epoch() const { return epochs_.front(); }
  double last_epoch() const { return epochs_.back(); }

 private:
  int nmax_ = 0;
  std::vector<double> epochs_;
  // coefficients_[e] holds g(n,m) and h(n,m) at epoch e, indexed by gh_index.
  std::vector<std::vector<double>> g_, h_;
};

}  // namespace magcomp
