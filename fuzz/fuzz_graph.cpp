// libFuzzer target: a graph file from bytes, loaded and validated as `grains validate` does
// (app/cli.cpp: load_graph = read the file, then parse_graph: JSON, schema, parameters,
// expressions, inputs, cycles, each node's own check of its files). LoadError is the documented
// answer to a bad graph; anything else is a finding.
#include <cstddef>
#include <cstdint>
#include <string>

#include "engine/graph.h"
#include "fuzz/fuzz.h"
#include "nodes/register.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace grains;
  register_builtin_nodes();
  const std::string text(reinterpret_cast<const char*>(data), size);
  // named as if it were in graphs/, so that the examples' relative files (data/...) resolve
  // and the nodes' file checks run on real files
  grains_fuzz::only_documented_errors<LoadError>(
      "fuzz_graph", [&] { (void)parse_graph(text, GRAINS_FUZZ_GRAPH_FILE); });
  return 0;
}
