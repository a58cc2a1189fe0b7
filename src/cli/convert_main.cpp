// magcomp_convert (also run as `magcomp convert`): MIT-schema HDF5 flight <-> rosbag. A program of
// its own because it links the ROS bag libraries, whose loading and start-up (about 15 ms) the
// other subcommands should not pay.
#include <console_bridge/console.h>
#include <ros/console.h>

#include <CLI/CLI.hpp>

#include "common.h"
#include "subcommands.h"

int main(int argc, char** argv) {
  // The rosbag library logs through console_bridge and rosconsole; the converter says what went
  // wrong itself, in one line.
  console_bridge::setLogLevel(console_bridge::CONSOLE_BRIDGE_LOG_NONE);
  if (ros::console::set_logger_level(ROSCONSOLE_DEFAULT_NAME, ros::console::levels::Fatal)) {
    ros::console::notifyLoggerLevelsChanged();
  }
  CLI::App app{"magcomp convert: IN.h5 OUT.bag or IN.bag OUT.h5 (lossless)"};
  app.name("magcomp convert");
  magcomp::cli::setup_convert(&app);
  return magcomp::cli::parse_and_run(app, argc, argv);
}
