// magcomp CLI: helpers.
#include "common.h"

#include <sys/stat.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>

#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/paths.h"
#include "magcomp/core/nav/flight_navigation.h"
#include "magcomp/core/nav/flight_run.h"
#include "magcomp/core/nav/map_reference.h"

namespace magcomp::cli {

int run_reporting_errors(const std::function<int()>& body) {
  exit_cleanly_on_truncated_file();
  try {
    return body();
  } catch (const Error& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 3;
  }
}

int parse_and_run(CLI::App& app, int argc, char** argv) {
  return run_reporting_errors([&] {
    try {
      app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      return app.exit(e);
    }
    return 0;
  });
}

void make_report_dir(const std::string& dir) {
  struct stat st {};
  if (::mkdir(dir.c_str(), 0755) != 0 && !(::stat(dir.c_str(), &st) == 0 && S_ISDIR(st.st_mode)))
    throw Error(dir + ": cannot create the report directory");
}

void run_report_page(const std::string& script_name, const std::string& dir,
                     const std::string& data) {
  const std::string script = share_dir() + "/scripts/" + script_name;
  const std::string cmdline = "/usr/bin/python3 '" + script + "' '" + dir + "'";
  std::fflush(nullptr);
  if (std::system(cmdline.c_str()) != 0)
    throw Error("--report " + dir + ": the page script " + script +
                " failed; the report's data is in " + dir + "/" + data);
  std::printf("report: %s/index.html\n", dir.c_str());
}

void add_map_references(FlightData* flight, const std::vector<std::string>& specs,
                        const std::string& track, const Model* model) {
  for (const std::string& spec : specs) {
    std::string path;
    if (!nav::names_map(spec, &path) || flight->has(spec)) continue;
    const nav::AnomalyMap map = nav::read_anomaly_map(path);
    nav::MapReference ref;
    if (track == "filter") {
      if (!model || !model->fitted())
        throw Error("--track filter: needs a fitted model (the filter navigates on its anomaly)");
      const nav::TrackPositions p =
          nav::filter_positions(*flight, nav::measured_anomaly_nT(*flight, *model), map);
      ref = nav::map_reference(*flight, map, nav::MapTrack::Given, Igrf::installed(), &p.lat_rad,
                               &p.lon_rad);
    } else {
      ref = nav::map_reference(*flight, map,
                               track == "ins" ? nav::MapTrack::Ins : nav::MapTrack::Truth,
                               Igrf::installed());
    }
    for (const std::string& note : ref.notes)
      std::cerr << "warning: " << path << ": " << note << "\n";
    if (ref.off_map > 0)
      std::cerr << "warning: " << path << ": " << ref.off_map << " of " << flight->size()
                << " samples lie off the map: no reference there\n";
    flight->set(spec, ref.field_nT);
  }
}

std::vector<OutputGuard::File> map_inputs(const std::string& option,
                                          const std::vector<std::string>& specs) {
  std::vector<OutputGuard::File> out;
  for (const std::string& spec : specs) {
    std::string path;
    if (nav::names_map(spec, &path)) out.push_back({option, path});
  }
  return out;
}

std::string figure(double v, const char* format) {
  if (!std::isfinite(v)) return "n/a";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

nlohmann::json json_figure(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}

std::vector<std::string> split_commas(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= s.size()) {
    const size_t comma = s.find(',', start);
    const std::string item =
        s.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    if (!item.empty()) out.push_back(item);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

FlightData read_flight(const std::string& path) {
  FlightData f = read_flight_h5(path);
  for (const std::string& note : f.read_notes()) std::cerr << "warning: " << note << "\n";
  return f;
}

std::vector<std::string> flight_paths(const std::string& option, const std::string& comma_list) {
  std::vector<std::string> paths = split_commas(comma_list);
  if (paths.empty()) throw Error(option + ": no file given ('" + comma_list + "')");
  return paths;
}

std::vector<FlightData> read_flights(const std::vector<std::string>& paths) {
  std::vector<FlightData> flights;
  for (const std::string& path : paths) flights.push_back(read_flight(path));
  return flights;
}

namespace {
// Whether two columns hold the same values bit for bit (NaN equal to NaN).
bool same_values(const FlightData::Column& a, const FlightData::Column& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), static_cast<size_t>(a.size()) * sizeof(double)) == 0;
}
}  // namespace

void require_distinct_flights(const std::vector<std::pair<std::string, const FlightData*>>& flights,
                              const std::string& scalar) {
  for (size_t i = 0; i < flights.size(); ++i)
    for (size_t j = i + 1; j < flights.size(); ++j) {
      const FlightData& a = *flights[i].second;
      const FlightData& b = *flights[j].second;
      if (a.size() != b.size() || a.size() == 0 || !same_values(a.tt(), b.tt())) continue;
      if (a.has(scalar) && b.has(scalar) && !same_values(a.column(scalar), b.column(scalar)))
        continue;
      throw Error(flights[j].first + ": " + b.source() + " is the flight " + flights[i].first +
                  " already gives (" + a.source() + ": the same time stamps and " + scalar +
                  " readings): give another flight of the aircraft");
    }
}

OutputGuard guard_for(const std::vector<std::string>& flights,
                      const std::vector<OutputGuard::File>& others) {
  std::vector<OutputGuard::File> inputs;
  for (const std::string& f : flights) inputs.push_back({"--data", f});
  inputs.insert(inputs.end(), others.begin(), others.end());
  return OutputGuard(inputs);
}

}  // namespace magcomp::cli
