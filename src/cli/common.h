// magcomp CLI: helpers shared by the subcommands.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"

namespace magcomp::cli {

/// Reads one HDF5 flight file and prints what the reader left out or repaired as `warning:` lines
/// on stderr (nothing is dropped without a word).
FlightData read_flight(const std::string& path);

/// Reads the comma-separated list of HDF5 flight files of a --data option (read_flight each).
std::vector<FlightData> read_flights(const std::string& comma_list);

/// Runs a program's body and turns an escaping exception into the one-line `error: ...` message
/// and exit status every magcomp program uses (2: bad input, magcomp::Error; 3: anything else).
int run_reporting_errors(const std::function<int()>& body);

/// Parses the command line into `app` and runs the chosen callback the same way (a usage error
/// prints CLI11's message and exits with its status).
int parse_and_run(CLI::App& app, int argc, char** argv);

/// Creates a report directory (or takes an existing one). Throws magcomp::Error naming it.
void make_report_dir(const std::string& dir);

/// Turns a report directory's data into DIR/index.html with the installed page script
/// (share/scripts/<script>, python3); a failing script is a warning naming `data` (what the
/// directory holds), not an error.
void run_report_page(const std::string& script, const std::string& dir, const std::string& data);

/// Splits "a,b,c".
std::vector<std::string> split_commas(const std::string& s);

}  // namespace magcomp::cli
