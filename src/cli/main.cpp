// magcomp: the command-line tool. Each subcommand is a thin shell over magcomp_core.
#include <unistd.h>

#include <console_bridge/console.h>
#include <ros/console.h>

#include <CLI/CLI.hpp>
#include <climits>
#include <cstring>
#include <iostream>
#include <string>

#include "common.h"
#include "magcomp/core/error.h"
#include "magcomp/core/paths.h"
#include "subcommands.h"

namespace {

/// `magcomp train ...` runs the magcomp_train executable beside this one (libtorch lives there,
/// so the other subcommands start in a millisecond).
int exec_train(int argc, char** argv) {
  const std::string train = magcomp::executable_dir() + "/magcomp_train";
  std::vector<char*> args;
  args.push_back(const_cast<char*>(train.c_str()));
  for (int i = 2; i < argc; ++i) args.push_back(argv[i]);
  args.push_back(nullptr);
  ::execv(train.c_str(), args.data());
  std::cerr << "error: " << train << ": cannot run (" << std::strerror(errno) << ")\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && std::string(argv[1]) == "train") return exec_train(argc, argv);
  // The rosbag library logs through console_bridge and rosconsole; the CLI says what went wrong
  // itself, in one line.
  console_bridge::setLogLevel(console_bridge::CONSOLE_BRIDGE_LOG_NONE);
  if (ros::console::set_logger_level(ROSCONSOLE_DEFAULT_NAME, ros::console::levels::Fatal)) {
    ros::console::notifyLoggerLevelsChanged();
  }
  CLI::App app{"magcomp: airborne magnetic compensation (Tolles-Lawson + physical terms)"};
  app.require_subcommand(1);
  magcomp::cli::add_simulate(app);
  magcomp::cli::add_calibrate(app);
  magcomp::cli::add_evaluate(app);
  magcomp::cli::add_diagnose(app);
  magcomp::cli::add_convert(app);
  magcomp::cli::add_info(app);
  app.add_subcommand("train",
                     "train a model's neural stage (runs magcomp_train; see magcomp train --help)");
  return magcomp::cli::run_reporting_errors([&] {
    try {
      app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      return app.exit(e);
    }
    return 0;
  });
}
