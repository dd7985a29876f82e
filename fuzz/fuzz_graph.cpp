// libFuzzer target: a graph file from bytes, loaded and validated as `grains validate` does
// (app/cli.cpp: load_graph = read the file, then parse_graph: JSON, schema, parameters,
// expressions, inputs, cycles, each node's own check of its files). LoadError is the documented
// answer to a bad graph; anything else is a finding.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "engine/graph.h"
#include "nodes/register.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace grains;
  register_builtin_nodes();
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    // named as if it were in graphs/, so that the examples' relative files (data/...) resolve
    // and the nodes' file checks run on real files
    Graph g = parse_graph(text, GRAINS_FUZZ_GRAPH_FILE);
    (void)g;
  } catch (const LoadError&) {
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_graph: unexpected exception: %s\n", e.what());
    std::abort();
  }
  return 0;
}
