// magcomp CLI: helpers shared by the subcommands.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/io/output_guard.h"
#include "magcomp/core/model/model.h"

namespace magcomp::cli {

/// Reads one HDF5 flight file and prints what the reader left out or repaired as `warning:` lines
/// on stderr (nothing is dropped without a word).
FlightData read_flight(const std::string& path);

/// The paths of a comma-separated option ("--data a.h5,b.h5"). Throws magcomp::Error "OPTION: no
/// file given" when it names none (",", "").
std::vector<std::string> flight_paths(const std::string& option, const std::string& comma_list);

/// Reads HDF5 flight files (read_flight each).
std::vector<FlightData> read_flights(const std::vector<std::string>& paths);

/// Throws magcomp::Error when two of `flights` (each with the option and path that named it) are
/// one flight: the same time stamps and the same readings of `scalar` (nT), sample for sample
/// (one file named twice, a link or a copy). A command that learns from several flights of an
/// aircraft, or checks a model on another, would count the one flight's evidence twice.
void require_distinct_flights(const std::vector<std::pair<std::string, const FlightData*>>& flights,
                              const std::string& scalar);

/// The output guard of a command that reads `flights` (each under --data) and `others`.
OutputGuard guard_for(const std::vector<std::string>& flights,
                      const std::vector<OutputGuard::File>& others);

/// Runs a program's body and turns an escaping exception into the one-line `error: ...` message
/// and exit status every magcomp program uses (2: bad input, magcomp::Error; 3: anything else).
int run_reporting_errors(const std::function<int()>& body);

/// Parses the command line into `app` and runs the chosen callback the same way (a usage error
/// prints CLI11's message and exits with its status).
int parse_and_run(CLI::App& app, int argc, char** argv);

/// Creates a report directory (or takes an existing one). Throws magcomp::Error naming it.
void make_report_dir(const std::string& dir);

/// Turns a report directory's data into DIR/index.html with the installed page script
/// (share/scripts/<script>, python3); a failing script is an error (magcomp::Error) naming the
/// directory and `data` (what it holds).
void run_report_page(const std::string& script, const std::string& dir, const std::string& data);

/// Resolves the reference fields a command reads: each of `specs` that names a map
/// ("map:M.h5") becomes a column of that name in `flight`: the map's anomaly along `track`
/// ("truth": lat/lon, "ins": the INS solution, "filter": the navigation filter on `model`'s
/// anomaly, which must be fitted) plus the IGRF and the diurnal (nav/map_reference.h). Prints
/// what a user must know as `warning:` lines. Other specs are left to the flight.
void add_map_references(FlightData* flight, const std::vector<std::string>& specs,
                        const std::string& track, const Model* model);

/// The maps a list of reference specs names, as the output guard's inputs (option `option`).
std::vector<OutputGuard::File> map_inputs(const std::string& option,
                                          const std::vector<std::string>& specs);

/// A figure for a table: printf(format, v), or "n/a" when v is not finite (nothing gave it).
std::string figure(double v, const char* format);

/// A figure for a JSON file: the number, or null when it is not finite.
nlohmann::json json_figure(double v);

/// Splits "a,b,c".
std::vector<std::string> split_commas(const std::string& s);

}  // namespace magcomp::cli
