// magcomp: the physical and mathematical constants every module shares, defined once.
#pragma once

namespace magcomp {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;  ///< rad per degree
constexpr double kRadToDeg = 180.0 / kPi;  ///< degrees per rad
constexpr double kStandardGravity_mps2 = 9.80665;
constexpr double kMeanEarthRadius_m = 6371000.0;  ///< local tangent planes; IGRF has its own
/// Beyond any magnetic field near the Earth (its main field is below 70,000 nT), nT: a value or a
/// figure above it comes from broken data, never from a magnetometer.
constexpr double kMaxField_nT = 1e6;

}  // namespace magcomp
