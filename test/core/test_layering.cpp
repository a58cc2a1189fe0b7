// The package's layering, read from its own sources: no #include in src/ or include/ runs from a
// lower folder to a higher one in the order doc/architecture.md states, and no two folders of
// one rank include each other. A new include against the order fails here, naming the line.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

namespace magcomp {
namespace {

namespace fs = std::filesystem;

// The folders by rank (doc/architecture.md): a file may include its own folder's headers and those
// of a lower rank; folders of one rank may include each other one way only.
const std::map<std::string, int>& ranks() {
  static const std::map<std::string, int> r = {
      {"core/error", 0},    {"core/math", 1},     {"core/io", 2},     {"core/geo", 3},
      {"core/model", 4},    {"core/fit", 5},      {"core/neural", 6}, {"core/apply", 7},
      {"core/evaluate", 8}, {"core/diagnose", 8}, {"core/stream", 8}, {"core/sim", 8},
      {"core/nav", 8},      {"neural", 9},        {"ros", 10},        {"nodes", 11},
      {"cli", 11}};
  return r;
}

// The folder of a path relative to the repository (src/... or include/magcomp/...).
std::string folder_of(std::string p) {
  for (const char* root : {"include/magcomp/", "src/"})
    if (p.rfind(root, 0) == 0) p = p.substr(std::string(root).size());
  if (p.rfind("core/error", 0) == 0) return "core/error";
  const size_t a = p.find('/');
  if (a == std::string::npos) return p;
  if (p.rfind("core/", 0) == 0) {
    const size_t b = p.find('/', a + 1);
    return b == std::string::npos ? p : p.substr(0, b);
  }
  return p.substr(0, a);
}

TEST(Layering, NoIncludeRunsAgainstTheOrder) {
  const fs::path repo(MAGCOMP_SOURCE_DIR);
  const std::regex include_line("^\\s*#\\s*include\\s+\"([^\"]+)\"");
  std::vector<std::string> against;
  std::map<std::string, std::set<std::string>> edges;
  int files = 0, includes = 0;
  for (const char* root : {"src", "include"}) {
    for (const auto& e : fs::recursive_directory_iterator(repo / root)) {
      if (!e.is_regular_file()) continue;
      const std::string ext = e.path().extension().string();
      if (ext != ".cpp" && ext != ".h") continue;
      const std::string rel = fs::relative(e.path(), repo).generic_string();
      const std::string from = folder_of(rel);
      ASSERT_TRUE(ranks().count(from)) << rel << ": its folder '" << from << "' has no rank";
      ++files;
      std::ifstream in(e.path());
      std::string line;
      int number = 0;
      std::smatch m;
      while (std::getline(in, line)) {
        ++number;
        if (!std::regex_search(line, m, include_line)) continue;
        const std::string inc = m[1];
        std::string target;
        if (inc.rfind("magcomp/", 0) == 0) {
          target = "include/" + inc;
        } else {  // relative to the including file
          target = fs::relative((e.path().parent_path() / inc).lexically_normal(), repo)
                       .generic_string();
        }
        if (target.rfind("include/magcomp/", 0) != 0 && target.rfind("src/", 0) != 0)
          continue;  // a generated message header or a test's
        const std::string to = folder_of(target);
        ASSERT_TRUE(ranks().count(to)) << rel << ":" << number << ": '" << inc << "' has no rank";
        ++includes;
        if (ranks().at(to) > ranks().at(from))
          against.push_back(rel + ":" + std::to_string(number) + ": " + from + " includes " + inc +
                            " (" + to + ")");
        if (to != from) edges[from].insert(to);
      }
    }
  }
  EXPECT_GT(files, 150);  // the walk found the sources
  EXPECT_GT(includes, 350);
  std::string list;
  for (const std::string& a : against) list += "\n  " + a;
  EXPECT_TRUE(against.empty()) << against.size() << " includes run against the order:" << list;
  for (const auto& [a, tos] : edges)
    for (const std::string& b : tos)
      EXPECT_FALSE(a < b && edges.count(b) && edges.at(b).count(a))
          << a << " and " << b << " include each other";
}

TEST(Layering, TheFolderOfAPathIsItsConcept) {
  EXPECT_EQ(folder_of("src/core/nav/ekf.cpp"), "core/nav");
  EXPECT_EQ(folder_of("include/magcomp/core/nav/ekf.h"), "core/nav");
  EXPECT_EQ(folder_of("include/magcomp/core/error.h"), "core/error");
  EXPECT_EQ(folder_of("src/ros/navigator_ros.cpp"), "ros");
  EXPECT_EQ(folder_of("include/magcomp/neural/trainer.h"), "neural");
  EXPECT_EQ(folder_of("src/cli/common.h"), "cli");
}

}  // namespace
}  // namespace magcomp
