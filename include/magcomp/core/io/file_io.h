// magcomp: every file the tools write goes through here: checked, atomic, never over an input.
#pragma once

#include <string>
#include <vector>

namespace magcomp {

/// Refuses an input that is not a regular file before it is opened: a pipe (FIFO), a device or a
/// directory would block or mislead a reader. `what` names it in the error ("model file", ...).
/// A missing path is left to the reader (its own "not found" message). Throws magcomp::Error.
void require_regular_file(const std::string& path, const std::string& what);

/// The path an output would take: the path itself when it exists (symbolic links followed), else
/// its directory's canonical path and its name; the path as given when its directory is missing.
/// Two spellings of one file ("m.yaml", "./m.yaml") give the same string.
std::string canonical_target(const std::string& path);

/// Refuses an output path before any work is done: one that names one of `inputs` (the same
/// file, by device and inode, or the same path), or an existing file that is not a regular file
/// (a device, a directory, a pipe). Throws magcomp::Error naming the path and why. The commands
/// declare their files to an OutputGuard (output_guard.h), which calls this.
void check_output_path(const std::string& path, const std::vector<std::string>& inputs = {});

/// A temporary path beside `path` (same directory, so the final rename is atomic).
std::string temporary_path(const std::string& path);

/// Moves a finished temporary file over `path` (after check_output_path); on failure removes the
/// temporary file and throws magcomp::Error naming `path`.
void commit_temporary(const std::string& tmp, const std::string& path,
                      const std::vector<std::string>& inputs = {});

/// Writes `content` to `path` atomically: checked path, temporary file, every write and the
/// close checked, then renamed into place. A reader never sees half a file, and a failure leaves
/// the old file as it was. Throws magcomp::Error naming the path.
void write_file_atomic(const std::string& path, const std::string& content,
                       const std::vector<std::string>& inputs = {});

/// A flight column read in place (FlightData maps plain HDF5 datasets) whose file another
/// program truncates meanwhile raises SIGBUS when read. After this call the process then says so
/// in one line on stderr and exits with status 2, as for any bad input; the command-line tools
/// call it first.
void exit_cleanly_on_truncated_file();

}  // namespace magcomp
