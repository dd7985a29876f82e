// Shared helpers for tests: graphs from inline JSON, temporary folders, the grains and
// grains-lab binaries.
#pragma once
#include <stdlib.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "engine/graph.h"
#include "engine/simulation.h"
#include "nodes/register.h"

namespace grains::test {

// A fresh empty folder under the system temp folder.
std::string temp_dir(const std::string& tag);
// Parses a graph from text; registers the built-in nodes first.
Graph graph_from(const std::string& json_text, const std::string& file = "test.json");
// Parses a graph that must be refused and returns the error; fails the test if it loads.
LoadError refusal_of(const std::string& json_text, const std::string& file = "bad.json");
// Writes text to a file and returns its path.
std::string write_file(const std::string& dir, const std::string& name, const std::string& text);
// Runs the grains binary with arguments; returns its exit code; output goes to `log`.
int run_grains(const std::string& args, const std::string& log);
// The same for the grains-lab binary (bench, features, laws).
int run_lab(const std::string& args, const std::string& log);
std::string read_text(const std::string& path);
// The fields of s between separators (a CSV line).
std::vector<std::string> split(const std::string& s, char sep);
std::string source_dir();

// A fixed sequence of numbers in [0, 1) (a linear congruential generator): jittered lattices
// that are the same on every machine and for every thread count.
class Sequence {
 public:
  explicit Sequence(uint32_t seed = 12345) : h_(seed) {}
  float next() {
    h_ = h_ * 1664525u + 1013904223u;
    return static_cast<float>(h_ >> 8) / 16777216.0f;
  }

 private:
  uint32_t h_;
};

// sets an environment variable for a scope, restoring what was there
struct ScopedEnv {
  const char* var;
  bool had;
  std::string saved;
  ScopedEnv(const char* v, const std::string& value) : var(v) {
    const char* before = getenv(var);
    had = before != nullptr;
    if (had) saved = before;
    setenv(var, value.c_str(), 1);
  }
  ~ScopedEnv() {
    if (had) setenv(var, saved.c_str(), 1);
    else unsetenv(var);
  }
};

}  // namespace grains::test
