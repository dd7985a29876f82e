// The dependency direction of DESIGN §1 and STYLE.md, read from the sources' #include lines:
// engine/ ← nodes/ ← the programs, and engine/ ← cli/ ← the programs. The product (`grains`, app/) and the lab (`grains-lab`, lab/)
// share only the engine, the nodes, the option checks (cli/) and the image module
// (viewer-offline/image.h); neither includes the other, and the viewer includes neither.
#include <algorithm>
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "tests/support/support.h"

namespace fs = std::filesystem;

namespace {

// For each folder of the program, what its files may include from the project's folders (a
// folder/ or one file); an include whose first part is none of these folders (a system or
// generated header) is not checked.
const std::vector<std::string> kFolders = {"engine",         "nodes", "cli",
                                           "viewer-offline", "app",   "lab"};
const std::map<std::string, std::vector<std::string>> kMayInclude = {
    {"engine", {"engine/"}},
    {"nodes", {"engine/", "nodes/"}},
    {"cli", {"engine/", "cli/"}},  // program.h maps the engine's errors to exit codes
    {"viewer-offline", {"engine/", "cli/", "viewer-offline/"}},
    {"app", {"engine/", "nodes/", "cli/", "viewer-offline/", "app/"}},
    {"lab", {"engine/", "nodes/", "cli/", "viewer-offline/image.h", "lab/"}},
};

// Within lab/, the sweep and the feature table share lab/bench_run.h and include not each other.
const std::set<std::pair<std::string, std::string>> kForbidden = {
    {"lab/bench.h", "lab/features.h"},
    {"lab/bench.cpp", "lab/features.h"},
    {"lab/features.h", "lab/bench.h"},
    {"lab/features.cpp", "lab/bench.h"},
};

// Known exceptions (file, include). Each must still be needed: the test fails when one is
// listed but the include is gone, so that the list never outlives its reason.
const std::set<std::pair<std::string, std::string>> kKnownExceptions = {};

struct Include {
  std::string file, target;  // relative to the source folder
  int line = 0;
};

std::vector<Include> project_includes() {
  const fs::path root = grains::test::source_dir();
  const std::regex quoted(R"re(^\s*#\s*include\s*"([^"]+)")re");
  std::vector<Include> out;
  for (const std::string& folder : kFolders)
    for (const auto& e : fs::recursive_directory_iterator(root / folder)) {
      const std::string ext = e.path().extension().string();
      if (!e.is_regular_file() || (ext != ".cpp" && ext != ".h" && ext != ".cl")) continue;
      std::ifstream in(e.path());
      int n = 0;
      for (std::string text; std::getline(in, text);) {
        ++n;
        std::smatch m;
        if (!std::regex_search(text, m, quoted)) continue;
        const std::string target = m[1].str();
        const std::string first = target.substr(0, target.find('/'));
        if (target.find('/') == std::string::npos ||
            std::find(kFolders.begin(), kFolders.end(), first) == kFolders.end())
          continue;
        out.push_back({fs::relative(e.path(), root).generic_string(), target, n});
      }
    }
  return out;
}

bool allowed(const Include& inc) {
  const std::string folder = inc.file.substr(0, inc.file.find('/'));
  for (const std::string& ok : kMayInclude.at(folder))
    if (ok.back() == '/' ? inc.target.starts_with(ok) : inc.target == ok) return true;
  return false;
}

}  // namespace

TEST_CASE("each folder includes only what the dependency direction allows", "[layout]") {
  const std::vector<Include> includes = project_includes();
  REQUIRE(includes.size() > 100);  // the sources were found
  std::set<std::pair<std::string, std::string>> seen_exceptions;
  for (const Include& inc : includes) {
    const std::pair<std::string, std::string> key{inc.file, inc.target};
    if (kKnownExceptions.count(key)) {
      seen_exceptions.insert(key);
      continue;
    }
    INFO(inc.file << ":" << inc.line << " includes " << inc.target);
    CHECK(allowed(inc));
    CHECK(kForbidden.count(key) == 0);
  }
  for (const auto& [file, target] : kKnownExceptions) {
    INFO("the known exception " << file << " -> " << target
                                << " is no longer needed: remove it from kKnownExceptions");
    CHECK(seen_exceptions.count({file, target}) == 1);
  }
}

TEST_CASE("stb_image_write's implementation is compiled in one translation unit", "[layout]") {
  // two static copies would link, silently, and differ in their settings (compression level)
  const fs::path root = grains::test::source_dir();
  std::vector<std::string> defining;
  for (const char* folder : {"engine", "nodes", "cli", "viewer-offline", "app", "lab", "bench"})
    for (const auto& e : fs::recursive_directory_iterator(root / folder)) {
      if (!e.is_regular_file()) continue;
      std::ifstream in(e.path());
      for (std::string text; std::getline(in, text);)
        if (text.find("#define STB_IMAGE_WRITE_IMPLEMENTATION") != std::string::npos)
          defining.push_back(fs::relative(e.path(), root).generic_string());
    }
  CHECK(defining == std::vector<std::string>{"viewer-offline/image.cpp"});
}
