// magcomp: where the package's own files are at run time (installed, or in the build tree).
#pragma once

#include <string>

namespace magcomp {

/// Whether `path` names an existing directory (following symbolic links).
bool is_directory(const std::string& path);

/// Directory of the running executable (from /proc/self/exe), "." if unknown.
std::string executable_dir();

/// The package's share directory, holding config/ (IGRF coefficients, scenarios, models) and
/// scripts/ (the report generator, the live plotter): $MAGCOMP_SHARE_DIR when set; else
/// <executable>/../share/magcomp or <executable>/../../share/magcomp when it holds config/ (a
/// catkin install space: the tools in bin/, the nodes in lib/magcomp/); else the source directory
/// the package was built from (the devel space and the tests).
std::string share_dir();

}  // namespace magcomp
