// magcomp: a recorded channel that follows a smooth curve of the flight's time (a battery's
// charge, a warm-up): a term of it writes any effect of that shape, and its flight cannot say
// which channel carries it.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"

namespace magcomp {

/// The channel's means over blocks of this length (s) are what the curve is fitted to: each
/// sensor's white noise, which a term's low-pass and the fit average away, is averaged out.
constexpr double kTimeTrendBlock_s = 5.0;
/// The curve: a polynomial of this degree in the time since the flight's first sample.
constexpr int kTimeTrendDegree = 3;
/// A channel whose block means the curve explains to at least this share of their variance, on
/// every flight, follows the flight's time.
constexpr double kTimeTrendShare = 0.99;

/// The share (0..1) of the variance of x's means over blocks of `block_s` seconds (samples `dt_s`
/// apart; blocks with a NaN skipped) that a polynomial of `degree` in time explains. NaN with
/// fewer than 20 blocks, or when the means do not vary.
double time_trend_share(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s,
                        double block_s = kTimeTrendBlock_s, int degree = kTimeTrendDegree);

/// A channel that follows the flights' time: its least time_trend_share over the flights.
struct TimeTrend {
  std::string channel;
  double share = 0;  ///< dimensionless, 0..1
};

/// `channel` when it follows a smooth curve of time on every flight (time_trend_share at least
/// kTimeTrendShare on each); nothing when a flight does not record it or it runs another course
/// there.
std::vector<TimeTrend> time_trend(const std::string& channel,
                                  const std::vector<const FlightData*>& flights);

}  // namespace magcomp
