// The graph model: a JSON graph file (DESIGN §2) parsed and validated into an immutable Graph.
// Nothing else reads JSON. Every bad input is refused here, before any frame runs, with the
// file, the JSON pointer and what is wrong.
#pragma once
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/node.h"
#include "engine/params.h"

namespace grains {

struct LoadError : std::runtime_error {
  LoadError(std::string file, std::string pointer, std::string message);
  std::string file, pointer, message;
};

struct NodeDesc {
  std::string name;
  std::string type;
  const NodeTypeInfo* info = nullptr;
  std::vector<int> inputs;  // indices into Graph::nodes, in authored order
  std::map<std::string, ParamValue> params;
  std::string pointer;  // JSON pointer of the node, e.g. /nodes/3
};

// The file formats a frame may be written as (output.formats): "ply" (DESIGN §6) and "vtp" (VTK
// XML PolyData with a .pvd collection, engine/vtk_io.h).
inline const std::vector<std::string>& output_format_names() {
  static const std::vector<std::string> names = {"ply", "vtp"};
  return names;
}

struct OutputDesc {
  std::string dir = "out";
  int every = 1;
  std::vector<std::string> attributes;
  std::vector<std::string> formats = {"ply"};  // each once, from output_format_names()
};

// Frames per second a graph may ask for: a frame of 1000 s to one of 1 us.
constexpr double kMinFps = 1e-3;
constexpr double kMaxFps = 1e6;

struct Graph {
  std::string file;      // path as given
  std::string base_dir;  // folder of the file, for relative paths in parameters
  std::string name;
  double fps = 24;
  int frames = 1;
  uint64_t seed = 0;
  std::vector<NodeDesc> nodes;
  OutputDesc output;
  std::vector<int> solvers;  // indices of solver nodes, authored order

  int find(const std::string& node_name) const;  // -1 when absent
};

// One `--set NODE.PARAM=VALUE`; VALUE is JSON when it parses as JSON, else a string.
struct Override {
  std::string node, param, value;
  // instead of a node's name: every node of this type (`grains run --opencl`); none is no error
  std::string type = "";
};
// Parses "NODE.PARAM=VALUE"; throws LoadError (pointer "--set") when malformed.
Override parse_override(const std::string& text);

// Reads, applies overrides and validates. Throws LoadError.
Graph load_graph(const std::string& path, const std::vector<Override>& overrides = {});
// Same from text (file names the source in errors).
Graph parse_graph(const std::string& text, const std::string& file,
                  const std::vector<Override>& overrides = {});
// Validates one authored parameter value against its declaration. Throws LoadError at pointer.
ParamValue parse_param_value(const ParamDecl& decl, const std::string& json_text,
                             const std::vector<std::string>& channel_names,
                             const std::string& file, const std::string& pointer);

}  // namespace grains
