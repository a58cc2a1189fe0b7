// libFuzzer target: the scenario YAML reader on arbitrary text (validation only: a scenario that
// loads is not simulated, which takes seconds).
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "magcomp/core/error.h"
#include "magcomp/core/sim/scenario.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path =
      "/tmp/magcomp_fuzz_scenario_" + std::to_string(::getpid()) + ".yaml";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data, 1, size, f);
  std::fclose(f);
  try {
    (void)magcomp::sim::load_scenario(path);
  } catch (const magcomp::Error&) {
  }
  return 0;
}
