#include "engine/cook.h"

#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>

#include "engine/frame_writer.h"
#include "engine/graph.h"

namespace grains {

void cook_node(const std::string& type,
               const std::vector<std::pair<std::string, std::string>>& params,
               ParticleStore& state, const CookOptions& opt) {
  using json = nlohmann::json;
  const NodeTypeInfo* info = find_node_type(type);
  if (!info) throw LoadError(opt.source, "", "unknown node type '" + type + "'");
  if (info->role != NodeRole::Pop && info->role != NodeRole::Source)
    throw LoadError(opt.source, "", "node type '" + type + "' does not act on particles");
  json node = {{"name", "node"}, {"type", type}, {"params", json::object()}};
  for (const auto& [name, value] : params) {
    json v;
    try {
      v = json::parse(value);
    } catch (const json::exception&) {
      v = value;
    }
    node["params"][name] = v;
  }
  json solver = {{"name", "solver"},
                 {"type", "solver"},
                 {"inputs", {"node"}},
                 {"params", {{"substeps", opt.substeps}, {"error_control", opt.error_control}}}};
  json nodes = json::array({node, solver});
  if (opt.ground) {
    nodes.push_back({{"name", "ground"},
                     {"type", "collider"},
                     {"params", {{"shape", "plane"}, {"translate", {0, opt.ground_y, 0}}}}});
    nodes[1]["params"]["colliders"] = {"ground"};
  }
  json g = {{"grains_graph", 1}, {"name", "cook"},       {"fps", opt.fps},
            {"frames", opt.frames}, {"seed", opt.seed}, {"nodes", nodes}};
  if (opt.substeps < 1) throw LoadError(opt.source, "--substeps", "must be at least 1");
  if (opt.frames < 1) throw LoadError(opt.source, "--frames", "must be at least 1");
  // errors point at the parameter as the user wrote it: "--set NAME", not the made graph's pointer
  auto as_set = [&](const LoadError& e) {
    std::string ptr = e.pointer;
    const std::string pre = "/nodes/0/params/";
    if (ptr.rfind(pre, 0) == 0) ptr = "--set " + ptr.substr(pre.size());
    return LoadError(opt.source, ptr, e.message);
  };
  Graph graph;
  try {
    graph = parse_graph(g.dump(), opt.source);
  } catch (const LoadError& e) {
    throw as_set(e);
  }
  Simulation sim(graph, opt.threads);
  sim.set_points(0, std::move(state));
  std::unique_ptr<FrameSink> writer;
  if (!opt.out_dir.empty())
    writer = std::make_unique<FrameWriter>(opt.out_dir, std::vector<std::string>{}, true);
  for (int f = 0; f < opt.frames; ++f) {
    try {  // an expression's value out of range at this frame
      sim.step_frame();
    } catch (const LoadError& e) {
      throw e.file == opt.source ? as_set(e) : e;
    }
    if (writer) writer->write(frame_output(sim.frame(), sim.object(0), true));
    spdlog::debug("cook {}: frame {}: {}", type, sim.frame(), frame_detail(sim.object(0).stats));
  }
  state = std::move(sim.object(0).pts);
}

}  // namespace grains
