// magcomp: time base conversions.
#include "magcomp/core/io/time_base.h"

#include <cmath>


namespace magcomp {
namespace {

// Days since 1970-01-01 of a civil date (proleptic Gregorian; Howard Hinnant's algorithm).
int64_t days_from_civil(int64_t y, unsigned m, unsigned d) {
  y -= m <= 2;
  const int64_t era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<int64_t>(doe) - 719468;
}

int64_t floor_div(int64_t a, int64_t b) { return a / b - ((a % b != 0) && ((a < 0) != (b < 0))); }

}  // namespace

void epoch_of(int year, int doy, double tt_s, int64_t* sec, int64_t* nsec) {
  const double whole = std::floor(tt_s);
  int64_t ns = std::llround((tt_s - whole) * 1e9);
  int64_t s =
      (days_from_civil(year, 1, 1) + doy - 1) * kSecondsPerDay + static_cast<int64_t>(whole);
  s += ns / 1000000000LL;
  ns %= 1000000000LL;
  *sec = s;
  *nsec = ns;
}

double tt_of(int64_t sec, int64_t nsec) {
  const int64_t day = floor_div(sec, kSecondsPerDay);
  return static_cast<double>(sec - day * kSecondsPerDay) + 1e-9 * static_cast<double>(nsec);
}

void year_doy_of(int64_t sec, int* year, int* doy) {
  const int64_t day = floor_div(sec, kSecondsPerDay);
  // civil_from_days, then the day of the year.
  const int64_t z = day + 719468;
  const int64_t era = (z >= 0 ? z : z - 146096) / 146097;
  const unsigned doe = static_cast<unsigned>(z - era * 146097);
  const unsigned yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  const unsigned doy_mar = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const unsigned mp = (5 * doy_mar + 2) / 153;
  const unsigned m = mp < 10 ? mp + 3 : mp - 9;
  const int64_t y = static_cast<int64_t>(yoe) + era * 400 + (m <= 2);
  *year = static_cast<int>(y);
  *doy = static_cast<int>(day - days_from_civil(y, 1, 1) + 1);
}

double decimal_year_of(int64_t sec, int64_t nsec) {
  int year = 0, doy = 0;
  year_doy_of(sec, &year, &doy);
  return decimal_year(year, doy, tt_of(sec, nsec));
}

double decimal_year(int year, double day_of_year, double seconds_of_day) {
  const bool leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
  const double days = leap ? 366.0 : 365.0;
  return year + (day_of_year - 1.0 + seconds_of_day / 86400.0) / days;
}

}  // namespace magcomp
