// magcomp convert: MIT-schema HDF5 flight <-> rosbag, lossless both ways.
#include <sys/stat.h>

#include <chrono>
#include <iostream>

#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/output_guard.h"
#include "magcomp/ros/bag_converter.h"
#include "subcommands.h"

namespace magcomp::cli {

void setup_convert(CLI::App* cmd) {
  auto in = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>();
  auto force = std::make_shared<bool>(false);
  auto allow_skip = std::make_shared<bool>(false);
  cmd->add_option("IN", *in, "input flight (.h5) or bag (.bag)")->required();
  cmd->add_option("OUT", *out, "output bag (.bag) or flight (.h5)")->required();
  cmd->add_flag("--force", *force, "overwrite OUT if it exists");
  cmd->add_flag("--allow-skip", *allow_skip,
                "convert even when IN holds objects outside the flight schema (groups, string or "
                "boolean datasets): they are left out, each named in a warning");
  cmd->callback([=] {
    auto ends = [](const std::string& s, const std::string& e) {
      return s.size() >= e.size() && s.compare(s.size() - e.size(), e.size(), e) == 0;
    };
    const auto t0 = std::chrono::steady_clock::now();
    OutputGuard guard({{"IN", *in}});
    guard.add_output("OUT", *out);
    if (ends(*in, ".h5") && ends(*out, ".bag")) {
      const FlightData f = read_flight_h5(*in);
      std::vector<std::string> left_out;
      for (const auto& note : f.read_notes()) {
        std::cerr << "warning: " << note << "\n";
        if (note.find("left out") != std::string::npos) left_out.push_back(note);
      }
      if (!left_out.empty() && !*allow_skip) {
        throw Error(*in + ": " + std::to_string(left_out.size()) +
                    " object(s) outside the flight schema would be left out (listed above); "
                    "convert is lossless, so it stops: pass --allow-skip to convert without them");
      }
      const rosio::ConvertReport r = rosio::flight_to_bag(f, *out, *force);
      std::cout << "wrote " << *out << ": " << r.samples << " samples x " << r.fields << " fields, "
                << r.messages << " messages";
    } else if (ends(*in, ".bag") && ends(*out, ".h5")) {
      struct stat st {};
      if (!*force && ::stat(out->c_str(), &st) == 0)
        throw Error(*out + ": exists; pass --force to overwrite");
      const rosio::ConvertReport r = rosio::bag_to_h5(*in, *out);
      std::cout << "wrote " << *out << ": " << r.samples << " samples x " << r.fields << " fields";
    } else {
      throw Error("convert: give IN.h5 OUT.bag or IN.bag OUT.h5 (got '" + *in + "' '" + *out +
                  "')");
    }
    std::cout << " in "
              << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()
              << " s\n";
  });
}

}  // namespace magcomp::cli
