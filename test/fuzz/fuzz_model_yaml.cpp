// libFuzzer target: the model YAML reader (and the term language inside it) on arbitrary text.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "magcomp/core/error.h"
#include "magcomp/core/model/model.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = "/tmp/magcomp_fuzz_model_" + std::to_string(::getpid()) + ".yaml";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data, 1, size, f);
  std::fclose(f);
  try {
    const magcomp::Model m = magcomp::load_model_yaml(path);
    (void)m.make_column_names();
    (void)m.scalar_lag_s();
  } catch (const magcomp::Error&) {
  }
  return 0;
}
