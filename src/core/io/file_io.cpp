// magcomp: checked, atomic file writes.
#include "magcomp/core/io/file_io.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "magcomp/core/error.h"

namespace magcomp {

void require_regular_file(const std::string& path, const std::string& what) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return;  // the reader says "not found" in its own words
  if (S_ISREG(st.st_mode)) return;
  const char* kind = S_ISFIFO(st.st_mode)                         ? "a pipe (FIFO)"
                     : S_ISDIR(st.st_mode)                        ? "a directory"
                     : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device"
                     : S_ISSOCK(st.st_mode)                       ? "a socket"
                                                                  : "not a regular file";
  throw Error(path + ": " + what + " is " + kind + ", not a regular file; refusing to read it");
}

std::string canonical_target(const std::string& path) {
  char buf[PATH_MAX];
  if (::realpath(path.c_str(), buf)) return buf;
  const auto slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : path.substr(0, slash + 1);
  const std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
  if (!::realpath(dir.c_str(), buf)) return path;
  return std::string(buf) + "/" + name;
}

void check_output_path(const std::string& path, const std::vector<std::string>& inputs) {
  if (path.empty()) throw Error("output path is empty");
  struct stat out {};
  const bool exists = ::stat(path.c_str(), &out) == 0;
  if (exists && !S_ISREG(out.st_mode)) {
    throw Error(path +
                ": exists and is not a regular file (a device, directory or pipe); "
                "refusing to replace it");
  }
  const std::string target = canonical_target(path);
  for (const std::string& in : inputs) {
    if (in.empty()) continue;
    struct stat st {};
    const bool same_file = exists && ::stat(in.c_str(), &st) == 0 && st.st_dev == out.st_dev &&
                           st.st_ino == out.st_ino;
    if (same_file || in == path || canonical_target(in) == target) {
      throw Error(path + ": is an input of this command (" + in + "); refusing to overwrite it");
    }
  }
}

std::string temporary_path(const std::string& path) {
  return path + ".tmp." + std::to_string(::getpid());
}

void commit_temporary(const std::string& tmp, const std::string& path,
                      const std::vector<std::string>& inputs) {
  try {
    check_output_path(path, inputs);  // again: it may have changed while the work was done
  } catch (...) {
    std::remove(tmp.c_str());
    throw;
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(tmp.c_str());
    throw Error(path + ": cannot move the written file into place (" + why + ")");
  }
}

void write_file_atomic(const std::string& path, const std::string& content,
                       const std::vector<std::string>& inputs) {
  check_output_path(path, inputs);
  const std::string tmp = temporary_path(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(path + ": cannot write (" + std::strerror(errno) + ")");
  size_t done = 0;
  while (done < content.size()) {
    const ssize_t w = ::write(fd, content.data() + done, content.size() - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      const std::string why = std::strerror(errno);
      ::close(fd);
      std::remove(tmp.c_str());
      throw Error(path + ": write failed (" + why + ")");
    }
    done += static_cast<size_t>(w);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(tmp.c_str());
    throw Error(path + ": write failed (" + why + ")");
  }
  commit_temporary(tmp, path, inputs);
}

namespace {
void on_bus_error(int) {
  static const char kMessage[] =
      "error: a file read in place was changed or truncated while it was read (SIGBUS)\n";
  const ssize_t written = ::write(2, kMessage, sizeof kMessage - 1);
  (void)written;
  ::_exit(2);
}
}  // namespace

void exit_cleanly_on_truncated_file() {
  struct sigaction action {};
  action.sa_handler = on_bus_error;
  sigemptyset(&action.sa_mask);
  ::sigaction(SIGBUS, &action, nullptr);
}

}  // namespace magcomp
