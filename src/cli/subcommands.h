// magcomp CLI: registration of each subcommand (one file per subcommand).
// `train` and `convert` are programs of their own (magcomp_train, magcomp_convert) that the
// magcomp executable runs, so the other subcommands load neither libtorch nor the ROS libraries.
#pragma once

#include <CLI/CLI.hpp>

namespace magcomp::cli {

void add_calibrate(CLI::App& app);
void add_evaluate(CLI::App& app);
void add_simulate(CLI::App& app);
void add_diagnose(CLI::App& app);
/// The options and action of `magcomp convert` on `cmd` (the magcomp_convert program's root:
/// the converter links the ROS bag libraries, which the other subcommands do not load).
void setup_convert(CLI::App* cmd);
void add_info(CLI::App& app);
void add_navigate(CLI::App& app);

}  // namespace magcomp::cli
