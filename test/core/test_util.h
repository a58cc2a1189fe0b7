// magcomp tests: small helpers (CSV reading, temporary paths, running the CLI).
#pragma once

#include <unistd.h>

#include <Eigen/Core>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace magcomp::test {

/// Reads a numeric CSV (optional header line) into a matrix.
inline Eigen::MatrixXd read_csv(const std::string& path, bool header,
                                std::vector<std::string>* names = nullptr) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error(path + ": cannot open");
  std::string line;
  std::vector<std::vector<double>> rows;
  bool first = true;
  while (std::getline(f, line)) {
    if (line.empty()) continue;
    std::stringstream s(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(s, cell, ',')) cells.push_back(cell);
    if (first && header) {
      if (names) *names = cells;
      first = false;
      continue;
    }
    first = false;
    std::vector<double> row;
    for (const auto& c : cells) row.push_back(std::stod(c));
    rows.push_back(row);
  }
  Eigen::MatrixXd m(rows.size(), rows.empty() ? 0 : rows[0].size());
  for (size_t r = 0; r < rows.size(); ++r)
    for (size_t c = 0; c < rows[r].size(); ++c) m(r, c) = rows[r][c];
  return m;
}

inline std::string reference_dir() { return MAGCOMP_REFERENCE_DIR; }
inline std::string source_dir() { return MAGCOMP_SOURCE_DIR; }

/// The temporary directories a test binary made: removed, with everything in them, when the
/// process that made them exits normally, whether its tests passed or failed. A death test's
/// child (another process) removes nothing.
class TempDirs {
 public:
  static TempDirs& instance() {
    static TempDirs dirs;
    return dirs;
  }
  std::string make(const std::string& tag) {
    const char* base = std::getenv("TMPDIR");
    const std::string pattern =
        std::string(base && *base ? base : "/tmp") + "/magcomp_" + tag + "_XXXXXX";
    std::vector<char> tmpl(pattern.begin(), pattern.end());
    tmpl.push_back('\0');
    if (!mkdtemp(tmpl.data()))
      throw std::runtime_error(pattern + ": cannot create: " + std::strerror(errno));
    std::lock_guard<std::mutex> lock(mutex_);
    dirs_.emplace_back(tmpl.data());
    return dirs_.back();
  }
  ~TempDirs() {
    if (getpid() != owner_) return;
    std::error_code ec;
    for (const auto& d : dirs_) std::filesystem::remove_all(d, ec);
  }

 private:
  TempDirs() : owner_(getpid()) {}
  pid_t owner_;
  std::mutex mutex_;
  std::vector<std::string> dirs_;
};

/// A fresh temporary directory for one test (removed when the test binary exits).
inline std::string temp_dir(const std::string& tag) { return TempDirs::instance().make(tag); }

/// Runs a shell command; returns its exit status and fills `output` with stdout + stderr.
inline int run(const std::string& cmd, std::string* output) {
  std::string full = cmd + " 2>&1";
  FILE* p = popen(full.c_str(), "r");
  if (!p) return -1;
  char buf[4096];
  std::string out;
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int status = pclose(p);
  if (output) *output = out;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

inline std::string cli() { return MAGCOMP_CLI; }

}  // namespace magcomp::test
