// libFuzzer target: a bag turned back into a flight, in memory (structure check, then rosbag)
// and streamed to a file (the one-pass reader, or rosbag's index when it cannot), on arbitrary
// bytes.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "magcomp/core/error.h"
#include "magcomp/ros/bag_converter.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = "/tmp/magcomp_fuzz_bag_" + std::to_string(::getpid()) + ".bag";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data, 1, size, f);
  std::fclose(f);
  static const std::string out = path + ".h5";
  try {
    (void)magcomp::rosio::bag_to_flight(path);
  } catch (const magcomp::Error&) {
  }
  try {
    (void)magcomp::rosio::bag_to_h5(path, out);
  } catch (const magcomp::Error&) {
  }
  std::remove(out.c_str());
  return 0;
}
