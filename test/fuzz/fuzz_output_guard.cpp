// libFuzzer target: the output guard on arbitrary paths (spellings with ./ and //, names of
// inputs, hard and symbolic links, directories, a pipe) in a scratch directory. The guard must
// either refuse (a magcomp::Error) or accept outputs none of which is an input or another output
// by device and inode; a crash or another exception is a finding.
#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "magcomp/core/error.h"
#include "magcomp/core/io/output_guard.h"

namespace {

const std::string& scratch() {
  static const std::string d = [] {
    std::string tmpl = "/tmp/magcomp_fuzz_guard_XXXXXX";
    if (!::mkdtemp(tmpl.data())) std::abort();
    const std::string dir = tmpl;
    for (const char* f : {"a.h5", "b.yaml", "c.json"})
      std::fclose(std::fopen((dir + "/" + f).c_str(), "w"));
    ::link((dir + "/a.h5").c_str(), (dir + "/hard.h5").c_str());
    ::symlink((dir + "/b.yaml").c_str(), (dir + "/soft.yaml").c_str());
    ::mkdir((dir + "/sub").c_str(), 0755);
    ::mkfifo((dir + "/pipe").c_str(), 0600);
    return dir;
  }();
  return d;
}

const char* kNames[] = {"a.h5", "b.yaml",   "c.json",       "hard.h5", "soft.yaml",    "sub",
                        "pipe", "new.yaml", "sub/new.yaml", "",        "missing/x.h5", "."};

std::string path_of(uint8_t b) {
  std::string p = kNames[(b & 0x0f) % 12];
  if (b & 0x10) p = "./" + p;
  if (b & 0x20) p = "sub/../" + p;
  if (b & 0x40)
    p = scratch() + "//" + p;
  else
    p = scratch() + "/" + p;
  return p;
}

bool same_file(const std::string& a, const std::string& b) {
  struct stat x {
  }, y{};
  return ::stat(a.c_str(), &x) == 0 && ::stat(b.c_str(), &y) == 0 && x.st_dev == y.st_dev &&
         x.st_ino == y.st_ino;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const size_t inputs = 1 + data[0] % 3;
  if (size < 1 + inputs) return 0;
  std::vector<magcomp::OutputGuard::File> in;
  for (size_t k = 0; k < inputs; ++k) in.push_back({"--in", path_of(data[1 + k])});
  magcomp::OutputGuard guard(in);
  std::vector<std::string> accepted;
  for (size_t k = 1 + inputs; k < size && k < 1 + inputs + 6; ++k) {
    const std::string out = path_of(data[k]);
    try {
      guard.add_output("--out", out);
      if (!out.empty()) accepted.push_back(out);
    } catch (const magcomp::Error&) {
    }
  }
  for (const std::string& o : accepted) {
    for (const auto& i : in)
      if (!i.path.empty() && same_file(o, i.path)) std::abort();  // an input would be overwritten
    int same = 0;
    for (const std::string& p : accepted) same += same_file(o, p) ? 1 : 0;
    if (same > 1) std::abort();  // two outputs on one file
  }
  guard.check_inputs_unchanged();  // nothing changed them
  return 0;
}
