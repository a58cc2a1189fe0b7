// magcomp: run-time locations of the package's files.
#include "magcomp/core/io/paths.h"

#include <sys/stat.h>
#include <unistd.h>

#include <climits>
#include <cstdlib>

#ifndef MAGCOMP_BUILD_SOURCE_DIR
#define MAGCOMP_BUILD_SOURCE_DIR "."
#endif

namespace magcomp {

bool is_directory(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

std::string executable_dir() {
  char buf[PATH_MAX];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n <= 0) return ".";
  const std::string p(buf, static_cast<size_t>(n));
  const auto slash = p.find_last_of('/');
  return slash == std::string::npos ? "." : p.substr(0, slash);
}

std::string share_dir() {
  if (const char* env = std::getenv("MAGCOMP_SHARE_DIR"); env && *env) return env;
  // bin/<exe> (the command-line tools) or lib/magcomp/<exe> (the nodes).
  for (const char* up : {"/../share/magcomp", "/../../share/magcomp"}) {
    const std::string installed = executable_dir() + up;
    if (is_directory(installed + "/config")) return installed;
  }
  return MAGCOMP_BUILD_SOURCE_DIR;
}

}  // namespace magcomp
