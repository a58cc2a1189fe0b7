// magcomp: the command-line tool. Each subcommand is a thin shell over magcomp_core.
#include <malloc.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <climits>
#include <cstring>
#include <iostream>
#include <string>

#include "common.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/paths.h"
#include "subcommands.h"

namespace {

/// `magcomp train ...` and `magcomp convert ...` run the program beside this one
/// (magcomp_train links libtorch, magcomp_convert the ROS bag libraries), so the other
/// subcommands load neither and start in a few milliseconds.
int exec_program(const char* program, int argc, char** argv) {
  const std::string path = magcomp::executable_dir() + "/" + program;
  std::vector<char*> args;
  args.push_back(const_cast<char*>(path.c_str()));
  for (int i = 2; i < argc; ++i) args.push_back(argv[i]);
  args.push_back(nullptr);
  ::execv(path.c_str(), args.data());
  std::cerr << "error: " << path << ": cannot run (" << std::strerror(errno) << ")\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  // Column-sized buffers (a few MB each) come and go all through a job: kept in the heap and
  // reused, rather than mapped and unmapped by the allocator each time, they are paged in once.
  mallopt(M_MMAP_THRESHOLD, 1 << 30);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  if (argc >= 2 && std::string(argv[1]) == "train")
    return exec_program("magcomp_train", argc, argv);
  if (argc >= 2 && std::string(argv[1]) == "convert")
    return exec_program("magcomp_convert", argc, argv);
  CLI::App app{"magcomp: airborne magnetic compensation (Tolles-Lawson + physical terms)"};
  app.require_subcommand(1);
  magcomp::cli::add_simulate(app);
  magcomp::cli::add_calibrate(app);
  magcomp::cli::add_evaluate(app);
  magcomp::cli::add_diagnose(app);
  app.add_subcommand("convert", "IN.h5 OUT.bag or IN.bag OUT.h5, lossless (runs magcomp_convert)");
  magcomp::cli::add_info(app);
  magcomp::cli::add_navigate(app);
  app.add_subcommand("train",
                     "train a model's neural stage (runs magcomp_train; see magcomp train --help)");
  return magcomp::cli::parse_and_run(app, argc, argv);
}
