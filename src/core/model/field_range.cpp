// magcomp: magnetic fields within what a magnetometer gives (field_range.h).
#include "magcomp/core/model/field_range.h"

#include <cmath>
#include <cstdio>

#include "magcomp/core/error.h"
#include "magcomp/core/math/constants.h"

namespace magcomp {

void require_field_range(const FlightData& data, const std::string& field, Eigen::Index first_row) {
  if (!data.has(field)) return;
  const FlightData::Column v = data.column(field);
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    if (!(std::abs(v[i]) > kMaxField_nT)) continue;  // within range, or NaN
    char buf[128];
    std::snprintf(buf, sizeof buf, "' holds %.6g nT at sample %ld", v[i],
                  static_cast<long>(first_row + i));
    throw Error(data.source() + ": field '" + field + buf +
                ", beyond any magnetic field (|value| <= 1e6 nT): not a magnetometer's reading");
  }
}

void require_model_fields_in_range(const Model& model, const FlightData& data,
                                   const std::vector<std::string>& others, Eigen::Index first_row) {
  require_field_range(data, model.scalar, first_row);
  for (const char* axis : {"_x", "_y", "_z"})
    require_field_range(data, model.vector + axis, first_row);
  for (const std::string& f : others) require_field_range(data, f, first_row);
}

}  // namespace magcomp
