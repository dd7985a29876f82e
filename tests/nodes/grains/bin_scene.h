// The OpenCL residency tests' scene: 1,000 grains of 1 cm (a jittered 0.2 m box, 2 cm apart)
// dropped in a bin 30 cm wide, 4 substeps a frame (or error control's), with use_opencl
// (test_opencl_hold.cpp, test_opencl_sleep_there.cpp).
#pragma once
#include <nlohmann/json.hpp>
#include <string>

#include "nodes/grains/grains_node.h"
#include "tests/support/support.h"

namespace grains::test {

struct BinScene {
  float far = 0;         // the bin's floor centre, this far from the origin along x and z (m)
  double drop = 0.15;    // the height of the grains' box's centre (m)
  bool sleeping = true;  // the grains node's default sleeping (else sleep_speed 0)
  // a ball of 4 cm radius that sweeps through the pile along x from 0.7 s to 0.8 s of the run,
  // still before and after
  bool pusher = false;
  bool pusher_mesh = false;  // the ball as a lumpy closed mesh (graphs/data/rock.obj, r ~ 4 cm)
  // an attribute node after the grains node that sets `probed` to this expression each substep
  const char* probe = nullptr;
  const char* probed = "probe";
  bool error_control = true;
  bool jacobi = false;  // contact_solver jacobi (else the default gauss_seidel)
  // with jacobi: the rows and planes found again every iteration
  // (update_*_during_iterations)
  bool rebuilds = false;
  int frames = 8;
  const char* file = "bin.json";  // the graph's name, under tests/
};

inline Graph bin_graph(const BinScene& b) {
  using json = nlohmann::json;
  const float far = b.far;
  auto plane = [&](const char* name, json normal, json at) {
    return json{{"name", name},
                {"type", "collider"},
                {"params", {{"shape", "plane"}, {"normal", normal}, {"translate", at}}}};
  };
  json nodes = json::array(
      {plane("ground", {0, 1, 0}, {far, 0, far}), plane("xm", {1, 0, 0}, {far - 0.15, 0, far}),
       plane("xp", {-1, 0, 0}, {far + 0.15, 0, far}), plane("zm", {0, 0, 1}, {far, 0, far - 0.15}),
       plane("zp", {0, 0, -1}, {far, 0, far + 0.15})});
  json colliders = {"ground", "xm", "xp", "zm", "zp"};
  if (b.pusher) {
    json params = {{"shape", "sphere"},
                   {"radius", 0.04},
                   {"translate", {"-0.2 + 4 * min(max($ST - 0.7, 0), 0.1)", 0.04, 0}}};
    if (b.pusher_mesh) {
      params.erase("radius");
      params["shape"] = "mesh", params["file"] = "../graphs/data/rock.obj", params["scale"] = 0.33;
    }
    nodes.push_back({{"name", "pusher"}, {"type", "collider"}, {"params", params}});
    colliders.push_back("pusher");
  }
  nodes.push_back({{"name", "sand"},
                   {"type", "source"},
                   {"params",
                    {{"shape", "box"},
                     {"center", {far, b.drop, far}},
                     {"size", {0.2, 0.2, 0.2}},
                     {"separation", 0.02},
                     {"jitter", 0.1}}}});
  nodes.push_back({{"name", "gravity"},
                   {"type", "force"},
                   {"inputs", {"sand"}},
                   {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}});
  json grains = {
      {"particle_separation", 0.02}, {"use_opencl", true}, {"friction_with_particles", 1}};
  if (!b.sleeping) grains["sleep_speed"] = 0;
  if (b.jacobi) grains["contact_solver"] = "jacobi";
  if (b.rebuilds) {
    grains["update_neighbors_during_iterations"] = true;
    grains["update_collisions_during_iterations"] = true;
  }
  nodes.push_back(
      {{"name", "grains"}, {"type", "grains"}, {"inputs", {"gravity"}}, {"params", grains}});
  std::string last = "grains";
  if (b.probe) {
    nodes.push_back({{"name", "probe"},
                     {"type", "attribute"},
                     {"inputs", {"grains"}},
                     {"params", {{"attribute", b.probed}, {"value", b.probe}}}});
    last = "probe";
  }
  nodes.push_back(
      {{"name", "solver"},
       {"type", "solver"},
       {"inputs", {last}},
       {"params",
        {{"substeps", 4}, {"error_control", b.error_control}, {"colliders", colliders}}}});
  json g = {{"grains_graph", 1}, {"fps", 24}, {"frames", b.frames}, {"seed", 5}, {"nodes", nodes}};
  return graph_from(g.dump(), source_dir() + "/tests/" + b.file);
}

// the first grains node's solver in the simulation's first object (null: none)
inline const GrainsSolver* bin_solver(const Simulation& sim) {
  for (const ChainNode& c : sim.object(0).chain)
    if (const GrainsSolver* s = c.impl ? grains_solver(*c.impl) : nullptr) return s;
  return nullptr;
}

}  // namespace grains::test
