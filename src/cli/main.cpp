// magcomp: the command-line tool. Each subcommand is a thin shell over magcomp_core.
#include <CLI/CLI.hpp>
#include <iostream>

#include "magcomp/core/error.h"
#include "subcommands.h"

int main(int argc, char** argv) {
  CLI::App app{"magcomp: airborne magnetic compensation (Tolles-Lawson + physical terms)"};
  app.require_subcommand(1);
  magcomp::cli::add_simulate(app);
  magcomp::cli::add_calibrate(app);
  magcomp::cli::add_evaluate(app);
  magcomp::cli::add_diagnose(app);
  magcomp::cli::add_convert(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const magcomp::Error& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 3;
  }
  return 0;
}
