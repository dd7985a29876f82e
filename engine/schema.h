// The graph format as a JSON Schema (draft-07), generated from the node types' parameter tables,
// so that an editor that reads JSON Schema checks and completes a graph as it is typed. The
// loader (graph.cpp) stays the judge: the schema states the structure (fields, types, menus,
// ranges, vector lengths), not what needs the whole graph (inputs naming nodes, cycles,
// expressions that parse, files that exist). `grains schema` prints it; docs/graph.schema.json
// is its committed copy, which the example graphs name in "$schema".
#pragma once
#include <string>

namespace grains {

// The schema for the registered node types, as indented JSON text ending in a newline.
std::string graph_schema_text();

}  // namespace grains
