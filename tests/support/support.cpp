#include "tests/support/support.h"

#include <catch2/catch.hpp>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace grains::test {

std::string temp_dir(const std::string& tag) {
  static std::atomic<int> counter{0};
  auto p =
      std::filesystem::temp_directory_path() /
      ("grains_test_" + tag + "_" + std::to_string(getpid()) + "_" + std::to_string(counter++));
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  return p.string();
}

Graph graph_from(const std::string& text, const std::string& file) {
  register_builtin_nodes();
  return parse_graph(text, file);
}

LoadError refusal_of(const std::string& text, const std::string& file) {
  try {
    graph_from(text, file);
  } catch (const LoadError& e) {
    return e;
  }
  FAIL("the graph loaded, but it should have been refused");
  return LoadError("", "", "");
}

std::string write_file(const std::string& dir, const std::string& name, const std::string& text) {
  std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  return path;
}

namespace {

int run_binary(const std::string& binary, const std::string& args, const std::string& log) {
  std::string cmd = binary + " " + args + " > " + log + " 2>&1";
  int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

}  // namespace

int run_grains(const std::string& args, const std::string& log) {
  return run_binary(GRAINS_BINARY, args, log);
}

int run_lab(const std::string& args, const std::string& log) {
  return run_binary(GRAINS_LAB_BINARY, args, log);
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string source_dir() {
  return GRAINS_SOURCE_DIR;
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, sep);) out.push_back(item);
  return out;
}

}  // namespace grains::test
