// magcomp tests: hostile input through the command line: the shared files and the check that a
// refusal is one `error:` line naming the file, field or key, with a non-zero exit.
#pragma once

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "magcomp/core/sim/simulator.h"
#include "scenario_cache.h"

namespace magcomp::test {

inline std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

inline bool exists(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0;
}

// Whether a command's output prints a NaN as a figure (" nan", "-nan", "(nan"; file names that
// hold "nan" do not count).
inline bool prints_nan(const std::string& out) {
  for (const char* t : {" nan", "-nan", "(nan", "\tnan"})
    if (out.find(t) != std::string::npos) return true;
  return false;
}

// Runs the CLI; expects exit 2 and exactly one output line, `error: ...` holding every `needle`.
inline void expect_refusal(const std::string& args, const std::vector<std::string>& needles) {
  std::string out;
  const int rc = run(cli() + " " + args, &out);
  EXPECT_EQ(rc, 2) << args << "\n" << out;
  std::string last;
  int errors = 0;
  std::istringstream lines(out);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("error: ", 0) == 0) {
      ++errors;
      last = line;
    }
  }
  EXPECT_EQ(errors, 1) << args << "\n" << out;
  for (const auto& n : needles) EXPECT_NE(last.find(n), std::string::npos) << args << "\n" << out;
}

struct Files {
  std::string dir, flight, model, fitted;
};

// A short simulated flight, a TL model for it and that model fitted.
inline const Files& files() {
  static Files f = [] {
    Files x;
    x.dir = temp_dir("hostile");
    x.flight = x.dir + "/f.h5";
    sim::write_simulation(scenario("rostest_short"), x.flight);
    x.model = source_dir() + "/config/models/tl_sim.yaml";
    x.fitted = x.dir + "/fitted.yaml";
    std::string out;
    if (run(cli() + " calibrate --data " + x.flight + " --model " + x.model + " --out " + x.fitted,
            &out) != 0)
      throw std::runtime_error(out);
    return x;
  }();
  return f;
}

inline std::string write(const std::string& name, const std::string& text) {
  const std::string p = files().dir + "/" + name;
  std::ofstream(p) << text;
  return p;
}

inline std::string model_with(const std::string& terms, const std::string& fit) {
  return write("m_" + std::to_string(std::hash<std::string>()(terms + fit)) + ".yaml",
               "scalar: mag_5_uc\nvector: flux_c\nterms: " + terms + "\nfit: " + fit + "\n");
}

// A copy of the flight with one field replaced.
inline std::string flight_with(const std::string& name, const std::string& field,
                               const Eigen::VectorXd& values) {
  FlightData f = read_flight_h5(files().flight);
  f.set(field, values);
  const std::string p = files().dir + "/" + name;
  write_flight_h5(f, p);
  return p;
}

}  // namespace magcomp::test
