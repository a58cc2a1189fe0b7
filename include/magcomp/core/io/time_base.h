// magcomp: the flights' time base (year, day of year, tt = seconds past midnight UTC) and epoch
// time, both ways, exact to the nanosecond.
#pragma once

#include <cstdint>

#include "magcomp/core/math/constants.h"

namespace magcomp {

constexpr int64_t kSecondsPerDay = 86400;

/// Epoch time (s since 1970-01-01 UTC, and ns) of (year, day of year 1..366, tt s past midnight
/// UTC). Whole seconds and the fraction of tt are kept apart: exact to the nanosecond (a double of
/// ~1.6e9 s resolves only 2.4e-7 s).
void epoch_of(int year, int doy, double tt_s, int64_t* sec, int64_t* nsec);

/// tt (s past midnight UTC) of an epoch time.
double tt_of(int64_t sec, int64_t nsec);

/// Calendar year and day of year (1..366) of an epoch time.
void year_doy_of(int64_t sec, int* year, int* doy);

/// Decimal year from a calendar year, day of year (1-based) and seconds past midnight UTC.
double decimal_year(int year, double day_of_year, double seconds_of_day);

/// Decimal year of an epoch time (what IGRF takes).
double decimal_year_of(int64_t sec, int64_t nsec);

}  // namespace magcomp
