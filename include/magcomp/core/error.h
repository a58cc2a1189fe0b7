// magcomp: the one exception type of the core library.
#pragma once

#include <stdexcept>
#include <string>

namespace magcomp {

/// Raised for any bad input. what() is a single line that names the file, field or parameter at
/// fault, so the command-line tools can print it as is and exit non-zero.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace magcomp
