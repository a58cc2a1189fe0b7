// magcomp: the guard between a command's inputs and its outputs (output_guard.h).
#include "magcomp/core/io/output_guard.h"

#include <sys/stat.h>

#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"

namespace magcomp {

OutputGuard::Snapshot OutputGuard::snapshot(const File& f) {
  Snapshot s;
  s.file = f;
  struct stat st {};
  if (::stat(f.path.c_str(), &st) != 0) return s;
  s.exists = true;
  s.dev = st.st_dev;
  s.ino = st.st_ino;
  s.size = st.st_size;
  s.mtime_ns = static_cast<long long>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec;
  return s;
}

OutputGuard::OutputGuard(const std::vector<File>& inputs) {
  for (const File& f : inputs)
    if (!f.path.empty()) inputs_.push_back(snapshot(f));
}

void OutputGuard::add_output(const std::string& option, const std::string& path) {
  if (path.empty()) return;
  const auto fail = [&](const std::string& why) { throw Error(option + " " + path + ": " + why); };
  struct stat out {};
  const bool exists = ::stat(path.c_str(), &out) == 0;
  if (exists && !S_ISREG(out.st_mode))
    fail("exists and is not a regular file (a device, directory or pipe); refusing to replace it");
  const std::string target = canonical_target(path);
  for (const Snapshot& in : inputs_) {
    const bool same_inode = exists && in.exists && in.dev == out.st_dev && in.ino == out.st_ino;
    if (same_inode || in.file.path == path || canonical_target(in.file.path) == target)
      fail("is an input of this command (" + in.file.option + " " + in.file.path +
           (same_inode && in.file.path != path ? ", the same file under another name" : "") +
           "); refusing to overwrite it");
  }
  for (const File& o : outputs_) {
    struct stat st {};
    const bool same_inode = exists && ::stat(o.path.c_str(), &st) == 0 && st.st_dev == out.st_dev &&
                            st.st_ino == out.st_ino;
    if (same_inode || canonical_target(o.path) == target)
      fail("is also the output " + o.option + "; two outputs cannot share a file");
  }
  outputs_.push_back({option, path});
}

void OutputGuard::add_output_dir(const std::string& option, const std::string& dir,
                                 const std::vector<std::string>& names) {
  if (dir.empty()) return;
  struct stat st {};
  if (::stat(dir.c_str(), &st) == 0 && !S_ISDIR(st.st_mode))
    throw Error(option + " " + dir + ": exists and is not a directory");
  for (const std::string& n : names) add_output(option, dir + "/" + n);
}

void OutputGuard::check_inputs_unchanged() const {
  for (const Snapshot& before : inputs_) {
    const Snapshot now = snapshot(before.file);
    if (now.exists != before.exists || now.dev != before.dev || now.ino != before.ino ||
        now.size != before.size || now.mtime_ns != before.mtime_ns)
      throw Error(before.file.path + " (" + before.file.option +
                  "): changed while it was read; nothing is written or reported from it");
  }
}

std::vector<std::string> OutputGuard::input_paths() const {
  std::vector<std::string> out;
  for (const Snapshot& s : inputs_) out.push_back(s.file.path);
  return out;
}

}  // namespace magcomp
