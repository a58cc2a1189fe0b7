// magcomp: the WGS-84 ellipsoid and the Earth's rotation, one definition for every frame and
// filter.
#pragma once

namespace magcomp {

/// Semi-major axis of the WGS-84 ellipsoid [m] (MagNav.jl's r_earth).
constexpr double kWgs84SemiMajor_m = 6378137.0;
/// Flattening of the WGS-84 ellipsoid [-].
constexpr double kWgs84Flattening = 1.0 / 298.257223563;
/// First eccentricity of the WGS-84 ellipsoid as MagNav.jl writes it (e_earth) [-]; its square
/// agrees with f(2 - f) to 1e-15.
constexpr double kWgs84Eccentricity = 0.0818191908426;
/// The Earth's rotation rate [rad/s] (MagNav.jl's ω_earth).
constexpr double kEarthRate_rps = 7.2921151467e-5;

}  // namespace magcomp
