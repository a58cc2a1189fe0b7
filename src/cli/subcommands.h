// magcomp CLI: registration of each subcommand (one file per subcommand).
#pragma once

#include <CLI/CLI.hpp>

namespace magcomp::cli {

void add_calibrate(CLI::App& app);
void add_evaluate(CLI::App& app);
void add_simulate(CLI::App& app);
void add_diagnose(CLI::App& app);
void add_convert(CLI::App& app);
void add_info(CLI::App& app);

}  // namespace magcomp::cli
