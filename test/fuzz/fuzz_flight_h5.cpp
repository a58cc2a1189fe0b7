// libFuzzer target: the flight HDF5 reader on arbitrary bytes. Anything but a clean
// magcomp::Error (or a flight) is a finding: a crash, an abort, another exception type.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "magcomp/core/error.h"
#include "magcomp/core/io/flight_data.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = "/tmp/magcomp_fuzz_h5_" + std::to_string(::getpid()) + ".h5";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data, 1, size, f);
  std::fclose(f);
  try {
    const magcomp::FlightData d = magcomp::read_flight_h5(path);
    if (d.size() > 1) (void)d.dt_s();
    // Columns are read on first use: a part of each (hyperslab), then each whole.
    for (const std::string& name : d.names()) (void)d.column_rows(name, d.size() / 3, d.size() / 3);
    for (const std::string& name : d.names()) (void)d.column(name);
  } catch (const magcomp::Error&) {
  }
  return 0;
}
