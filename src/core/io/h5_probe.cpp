// magcomp: the HDF5 structure walked in a child process first (h5_probe.h).
#include "magcomp/core/io/h5_probe.h"

#include <hdf5.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "h5_link_names.h"

namespace magcomp {

std::string probe_h5_structure(const std::string& path, unsigned long long read_values) {
  // MAGCOMP_HDF5_PROBE=0 turns the probe off: the fuzz target does, to feed libFuzzer fast and
  // see the library's own crashes (scripts/fuzz replays them through the probe).
  if (const char* env = std::getenv("MAGCOMP_HDF5_PROBE"); env && std::string(env) == "0")
    return "";
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) return "";  // no child: read without the probe
  if (pid == 0) {
    // The library's faults end the child by their signal (the parent's handlers, such as the
    // in-place reader's SIGBUS message, are not the child's business).
    for (int sig : {SIGBUS, SIGSEGV, SIGFPE, SIGILL, SIGABRT}) std::signal(sig, SIG_DFL);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    if (file >= 0) {
      std::vector<std::string> names;
      H5Literate(file, H5_INDEX_NAME, H5_ITER_NATIVE, nullptr, append_h5_link_name, &names);
      for (const std::string& name : names) {
        H5O_info_t info;
        if (H5Oget_info_by_name2(file, name.c_str(), &info, H5O_INFO_BASIC, H5P_DEFAULT) < 0 ||
            info.type != H5O_TYPE_DATASET)
          continue;
        const hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
        if (ds < 0) continue;
        const hid_t type = H5Dget_type(ds);
        if (type >= 0) {
          (void)H5Tget_class(type);
          H5Tclose(type);
        }
        const hid_t space = H5Dget_space(ds);
        unsigned long long n = 0;  // values declared (0: not a simple shape)
        if (space >= 0) {
          hsize_t dims[8];
          const int rank = H5Sget_simple_extent_ndims(space);
          if (rank >= 0 && rank <= 8 && H5Sget_simple_extent_dims(space, dims, nullptr) >= 0) {
            n = 1;
            for (int k = 0; k < rank; ++k) {
              if (dims[k] != 0 && n > read_values / dims[k]) {
                n = 0;  // more than read_values: not read here
                break;
              }
              n *= dims[k];
            }
          }
          H5Sclose(space);
        }
        const hsize_t stored = H5Dget_storage_size(ds);
        // The values themselves, where few enough and the file stores enough bytes for them (the
        // readers refuse the rest before reading).
        if (n > 0 && n <= read_values && stored > 0 && n <= stored * 1000) {
          std::vector<double> values(n);
          (void)H5Dread(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data());
        }
        H5Dclose(ds);
      }
      H5Fclose(file);
    }
    ::_exit(0);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFSIGNALED(status)) return "signal " + std::to_string(WTERMSIG(status));
  if (WIFEXITED(status) && WEXITSTATUS(status) != 0)
    return "exit " + std::to_string(WEXITSTATUS(status));
  return "";
}

}  // namespace magcomp
