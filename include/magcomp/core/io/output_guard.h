// magcomp: the one guard every command puts between its inputs and its outputs. Declared before
// any work: no output may be an input (by path, by canonical path, or by device and inode, so hard
// and symbolic links count), a non-regular file, or the same file as another output; and no input
// may change while the command reads it (its size and modification time are taken at the start
// and compared before anything is written or reported).
#pragma once

#include <sys/types.h>
#include <string>
#include <utility>
#include <vector>

namespace magcomp {

class OutputGuard {
 public:
  /// One file the command reads or writes: the option that names it ("--data") and its path.
  struct File {
    std::string option, path;
  };

  /// The command's inputs, each with its option; empty paths are left out. Their identity, size
  /// and modification time are taken now.
  explicit OutputGuard(const std::vector<File>& inputs);

  /// Declares an output and checks it at once against the inputs and the outputs declared
  /// before it. Throws magcomp::Error "OPTION PATH: why" when the path is empty, exists and is
  /// not a regular file, is an input, or is another output. An empty path is no output (skipped).
  void add_output(const std::string& option, const std::string& path);

  /// Declares the files a command writes into directory `dir` (a --report): each of `names` is an
  /// output as above; `dir` itself must be a directory or not exist.
  void add_output_dir(const std::string& option, const std::string& dir,
                      const std::vector<std::string>& names);

  /// Throws magcomp::Error "PATH (OPTION): changed while it was read" when an input's size,
  /// modification time or identity differs from the start: nothing is to be written or reported
  /// from it.
  void check_inputs_unchanged() const;

  /// The input paths (for the atomic writers' own last check).
  std::vector<std::string> input_paths() const;

 private:
  struct Snapshot {
    File file;
    bool exists = false;
    dev_t dev = 0;
    ino_t ino = 0;
    off_t size = 0;
    long long mtime_ns = 0;
  };
  static Snapshot snapshot(const File& f);

  std::vector<Snapshot> inputs_;
  std::vector<File> outputs_;
};

}  // namespace magcomp
