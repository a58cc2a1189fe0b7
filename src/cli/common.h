// magcomp CLI: helpers shared by the subcommands.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "magcomp/core/flight_data.h"

namespace magcomp::cli {

/// Reads the comma-separated list of HDF5 flight files of a --data option.
std::vector<FlightData> read_flights(const std::string& comma_list);

/// Splits "a,b,c".
std::vector<std::string> split_commas(const std::string& s);

}  // namespace magcomp::cli
