// magcomp: the magnetic fields a model reads hold what a magnetometer can give. A value beyond any
// magnetic field near the Earth (kMaxField_nT) makes every figure computed from it meaningless
// (an rms of inf, a residual of 1e150): such a flight is refused where it is used, by field and
// sample, before a figure is printed or a model written. NaN is a missing sample, not refused.
#pragma once

#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// Throws magcomp::Error "FILE: field 'F' holds V nT at sample I, beyond any magnetic field"
/// when a value of `field` (nT) is infinite or its magnitude exceeds kMaxField_nT. A field the
/// flight lacks is left to the reader that needs it. `data` may be a row slice of a flight
/// (FlightData::rows) starting at row `first_row`: only those rows are read, and the sample is
/// named by its row in the flight.
void require_field_range(const FlightData& data, const std::string& field,
                         Eigen::Index first_row = 0);

/// The same for the model's scalar, its vector magnetometer's three components and `others`
/// (a reference field).
void require_model_fields_in_range(const Model& model, const FlightData& data,
                                   const std::vector<std::string>& others = {},
                                   Eigen::Index first_row = 0);

}  // namespace magcomp
