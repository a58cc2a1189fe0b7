// libFuzzer target: a bag turned back into a flight (structure check, then rosbag) on arbitrary
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
  try {
    (void)magcomp::rosio::bag_to_flight(path);
  } catch (const magcomp::Error&) {
  }
  return 0;
}
