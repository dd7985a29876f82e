// Parameter conformance (STYLE.md, after Gaffer): for every node type and every parameter it
// declares, changing the parameter from its default changes the result. A parameter that is
// accepted but ignored fails here. Each node runs in a small scene where it acts; some
// parameters need context (a shape's radius matters only for that shape), given per parameter.
#include <catch2/catch.hpp>
#include <cmath>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>

#include "tests/support/support.h"

using namespace grains;
using json = nlohmann::json;

namespace {

// A different value for a parameter, within its declared range.
json changed_value(const ParamDecl& d) {
  auto clampv = [&](double v) {
    if (d.has_max) v = std::min(v, d.max);
    if (d.has_min && v <= d.min) v = d.min + (d.has_max ? (d.max - d.min) * 0.5 : 1.0);
    return v;
  };
  switch (d.type) {
    case ParamType::Float: {
      double v = d.def[0] == 0 ? 0.5 : d.def[0] * 0.3;
      if (d.has_max && d.def[0] >= d.max) v = d.max * 0.5;
      return clampv(v);
    }
    case ParamType::Int: return static_cast<int>(clampv(d.def[0] > 2 ? std::floor(d.def[0] / 3) : d.def[0] + 2));
    case ParamType::Toggle: return d.def[0] == 0;
    case ParamType::Vec3: return json::array({d.def[0] + 0.3, d.def[1] + 0.5, d.def[2] + 0.7});
    case ParamType::Menu:
      for (const auto& m : d.menu)
        if (m != d.def_string) return m;
      return d.def_string;
    case ParamType::String: return d.def_string + "x";
    case ParamType::StringList: return json::array();
  }
  return nullptr;
}

// The final state of a graph, reduced to what a user would see.
struct Outcome {
  std::vector<float> P, v;
  std::map<std::string, std::vector<int32_t>> groups;
  size_t points = 0;
  std::vector<int32_t> prims;  // the constraints' endpoints
  std::vector<float> strain;
  // every other point attribute (impact data, targetP, ...) and the collision feedback
  std::map<std::string, std::vector<float>> floats;
  std::map<std::string, std::vector<int32_t>> ints;
  std::vector<float> feedback;
  bool operator==(const Outcome& o) const {
    return P == o.P && v == o.v && groups == o.groups && points == o.points && prims == o.prims &&
           strain == o.strain && floats == o.floats && ints == o.ints && feedback == o.feedback;
  }
};

Outcome run(const json& graph, int frames) {
  Graph g = test::graph_from(graph.dump(), test::source_dir() + "/tests/conformance.json");
  Simulation sim(g, 1);
  for (int f = 0; f < frames; ++f) sim.step_frame();
  Outcome o;
  const ParticleStore& pts = sim.object(0).pts;
  o.points = pts.size();
  o.P = pts.find("P")->f;
  o.v = pts.find("v")->f;
  for (const auto& [name, a] : pts.attributes()) {
    if (name.rfind("group_", 0) == 0) o.groups[name] = a.i;
    if (a.type == AttribType::Int) o.ints[name] = a.i;
    else o.floats[name] = a.f;
  }
  o.prims = pts.prim_points();
  if (const float* e = pts.prim_f_if("strain")) o.strain.assign(e, e + pts.prim_count());
  for (const auto& c : sim.object(0).stats.colliders)
    o.feedback.insert(o.feedback.end(), {c.force.x, c.force.y, c.force.z, c.torque.x, c.torque.y, c.torque.z});
  return o;
}

// A scene for one node type: the node under test is named "n"; params are merged in.
using Scene = std::function<json(const json& params)>;

json base_graph(json nodes) {
  return {{"grains_graph", 1}, {"fps", 24}, {"frames", 12}, {"seed", 5}, {"nodes", nodes}};
}

// Grains of mixed sizes in a loose heap above a tilted ground, with some spin of velocities.
json heap_source(double sep = 0.1) {
  return {{"name", "src"}, {"type", "source"},
          {"params", {{"shape", "box"}, {"size", {0.5, 0.6, 0.5}}, {"center", {0, 0.4, 0}},
                      {"separation", sep}, {"jitter", 0.2}, {"velocity", {0.6, -0.5, 0.2}},
                      {"mass", 2}}}};
}

json ground(double tilt = 8) {
  return {{"name", "ground"}, {"type", "collider"},
          {"params", {{"shape", "plane"}, {"rotate", {tilt, 0, tilt / 2}}, {"bounce", 0.4}}}};
}

std::map<std::string, Scene> scenes() {
  std::map<std::string, Scene> s;
  s["source"] = [](const json& p) {
    json src = {{"name", "n"}, {"type", "source"}, {"params", {{"size", {0.4, 0.4, 0.4}}, {"separation", 0.1}}}};
    src["params"].update(p);
    return base_graph({src,
                       {{"name", "g"}, {"type", "force"}, {"inputs", {"n"}}, {"params", {{"force", {0, -9.81, 0}}}}},
                       ground(),
                       {{"name", "s"}, {"type", "solver"}, {"inputs", {"g"}},
                        {"params", {{"substeps", 2}, {"error_control", false}, {"colliders", {"ground"}}}}}});
  };
  auto pop = [](const std::string& type, json defaults) {
    return [type, defaults](const json& p) {
      json n = {{"name", "n"}, {"type", type}, {"inputs", {"g"}}, {"params", defaults}};
      n["params"].update(p);
      return base_graph({heap_source(),
                         {{"name", "g"}, {"type", "force"}, {"inputs", {"src"}},
                          {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}},
                         n, ground(),
                         {{"name", "s"}, {"type", "solver"}, {"inputs", {"n"}},
                          {"params", {{"substeps", 2}, {"error_control", false}, {"colliders", {"ground"}}}}}});
    };
  };
  s["force"] = pop("force", {{"force", {0.5, 1, 0}}});
  s["group"] = pop("group", {{"group_name", "g1"}, {"size", {0.5, 0.3, 0.5}}});
  s["kill"] = pop("kill", {{"center", {0, 0.5, 0}}, {"size", {0.3, 0.3, 0.3}}});
  s["attribute"] = pop("attribute", {{"attribute", "friction"}, {"value", "$TY"}});
  s["grains"] = [](const json& p) {
    json n = {{"name", "n"}, {"type", "grains"}, {"inputs", {"g"}},
              {"params", {{"particle_separation", 0.1}, {"constraint_iterations", 6},
                          {"assume_uniform_radius", false}}}};
    n["params"].update(p);
    json fine = heap_source(0.05);
    fine["name"] = "fine";
    fine["params"]["center"] = {0.1, 0.9, 0};
    // pins need a targetstiffness attribute: a target node (lifting the targets 0.3 m) joins
    // the chain when the pin parameters are authored, in both runs of the comparison
    const bool pins = p.contains("target_weight") || p.contains("target_stiffness");
    // shape matching needs primitives: a plate of grains joined by edges joins the heap
    const bool plate = p.contains("enable_rigid_shape_matching");
    json merge_inputs = {"src", "fine"};
    json nodes = {heap_source(), fine};
    if (plate) {
      nodes.push_back({{"name", "plate"}, {"type", "source"},
                       {"params", {{"shape", "file"}, {"file", "data/rigid_plate.ply"}, {"separation", 0.1},
                                   {"velocity", {0, -1, 0}}}}});
      merge_inputs.push_back("plate");
    }
    nodes.push_back({{"name", "m"}, {"type", "merge"}, {"inputs", merge_inputs}});
    nodes.push_back({{"name", "g"}, {"type", "force"}, {"inputs", {"m"}},
                     {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}});
    if (pins) {
      nodes.push_back({{"name", "t"}, {"type", "target"}, {"inputs", {"g"}},
                       {"params", {{"translate", {0, 0.3, 0}}, {"stiffness", 0.01}}}});
      n["inputs"] = {"t"};
    }
    nodes.push_back(n);
    nodes.push_back(ground());
    nodes.push_back({{"name", "s"}, {"type", "solver"}, {"inputs", {"n"}},
                     {"params", {{"substeps", 2}, {"error_control", false}, {"colliders", {"ground"}}}}});
    return base_graph(nodes);
  };
  s["target"] = [](const json& p) {
    json n = {{"name", "n"}, {"type", "target"}, {"inputs", {"g"}}, {"params", json::object()}};
    n["params"].update(p);
    return base_graph({heap_source(),
                       {{"name", "g"}, {"type", "force"}, {"inputs", {"src"}},
                        {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}},
                       n,
                       {{"name", "gr"}, {"type", "grains"}, {"inputs", {"n"}},
                        {"params", {{"target_stiffness", 10}, {"constraint_iterations", 6}}}},
                       ground(),
                       {{"name", "s"}, {"type", "solver"}, {"inputs", {"gr"}},
                        {"params", {{"substeps", 2}, {"error_control", false}, {"colliders", {"ground"}}}}}});
  };
  // explicit constraints: a connected sheet of overlapping grains (pscale 0.06 at 0.1 m) dropped
  // on a sphere, and a connected line of grains (a strand) beside it
  s["grains_constraints"] = [](const json& p) {
    json n = {{"name", "n"}, {"type", "grains"}, {"inputs", {"g"}},
              {"params", {{"particle_separation", 0.1}, {"constraint_iterations", 6}}}};
    n["params"].update(p);
    json sheet = {{"name", "sheet"}, {"type", "source"},
                  {"params", {{"shape", "grid"}, {"size", {0.8, 0, 0.8}}, {"center", {0, 0.5, 0}},
                              {"separation", 0.1}, {"pscale", 0.06}, {"connect_radius", 1.5}}}};
    json line = {{"name", "line"}, {"type", "source"},
                 {"params", {{"shape", "grid"}, {"size", {0.8, 0, 0}}, {"center", {0.2, 0.8, 0.6}},
                             {"separation", 0.1}, {"connect_radius", 1.1}}}};
    json ball = {{"name", "ball"}, {"type", "collider"}, {"params", {{"shape", "sphere"}, {"radius", 0.3}}}};
    return base_graph({sheet, line, {{"name", "m"}, {"type", "merge"}, {"inputs", {"sheet", "line"}}},
                       {{"name", "g"}, {"type", "force"}, {"inputs", {"m"}},
                        {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}},
                       n, ground(), ball,
                       {{"name", "s"}, {"type", "solver"}, {"inputs", {"n"}},
                        {"params", {{"substeps", 2}, {"error_control", false}, {"colliders", {"ground", "ball"}}}}}});
  };
  s["collider"] = [](const json& p) {
    json c = {{"name", "n"}, {"type", "collider"}, {"params", {{"shape", "box"}, {"size", {2, 0.2, 2}}}}};
    c["params"].update(p);
    return base_graph({heap_source(),
                       {{"name", "g"}, {"type", "force"}, {"inputs", {"src"}},
                        {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}},
                       c,
                       {{"name", "s"}, {"type", "solver"}, {"inputs", {"g"}},
                        {"params", {{"substeps", 2}, {"error_control", false}, {"colliders", {"n"}}}}}});
  };
  s["solver"] = [](const json& p) {
    // a grains node below: error control acts on what grains report
    json sv = {{"name", "n"}, {"type", "solver"}, {"inputs", {"gr"}}, {"params", {{"colliders", {"ground"}}}}};
    sv["params"].update(p);
    return base_graph({heap_source(),
                       {{"name", "g"}, {"type", "force"}, {"inputs", {"src"}},
                        {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}},
                       {{"name", "gr"}, {"type", "grains"}, {"inputs", {"g"}},
                        {"params", {{"particle_separation", 0.1}}}},
                       ground(), sv});
  };
  return s;
}

// Context a parameter needs to matter, and non-generic changed values.
struct Special {
  json context;       // merged into both runs
  json changed;       // the changed value (null: generic)
  std::string scene = "";  // the scene to run in (empty: the node type's own)
};
std::map<std::string, Special> specials() {
  return {
      // source
      {"source.radius", {{{"shape", "sphere"}}, nullptr}},
      {"source.size", {json::object(), json::array({0.3, 0.6, 0.5})}},
      {"source.file", {{{"shape", "file"}, {"file", "data/points_a.ply"}}, "data/points_b.ply"}},
      {"source.shape", {json::object(), "sphere"}},
      {"source.packing", {json::object(), "hexagonal"}},
      {"source.birth_frame", {json::object(), 3}},
      {"source.rate", {{{"emission", "rate"}}, 50}},
      {"source.start_frame", {{{"emission", "rate"}, {"rate", 100}}, 4}},
      {"source.end_frame", {{{"emission", "rate"}, {"rate", 100}}, 3}},
      {"source.density", {{{"density", 100}}, 300}},  // mass: the scene's force is in newtons
      {"source.mass", {json::object(), 3}},
      {"source.group", {json::object(), "fresh"}},
      {"source.activation", {json::object(), 0}},
      // group
      {"group.group_name", {json::object(), "other"}},
      {"group.radius", {{{"rule", "sphere"}}, 0.2}},
      {"group.attribute", {{{"rule", "attribute"}, {"attribute", "id"}, {"value", 10}}, "P_x"}},
      {"group.compare", {{{"rule", "attribute"}, {"attribute", "id"}, {"value", 10}}, "<"}},
      {"group.value", {{{"rule", "attribute"}, {"attribute", "id"}, {"value", 10}}, 30}},
      {"group.operation", {{{"rule", "sphere"}, {"radius", 0.2}}, "subtract"}},
      {"group.activation", {json::object(), 0}},
      // force
      {"force.group", {json::object(), "nobody"}},
      {"force.wind", {{{"drag", 1}}, json::array({1, 0, 0})}},
      {"force.ignore_mass", {{{"force", {0, 1, 0}}}, true}},
      {"force.activation", {json::object(), 0}},
      // kill
      {"kill.radius", {{{"shape", "sphere"}}, 0.3}},
      {"kill.activation", {json::object(), 0}},
      // attribute
      {"attribute.activation", {json::object(), 0}},
      {"attribute.type", {{{"attribute", "made"}}, "vector"}},
      {"attribute.value", {json::object(), "2 * $TY"}},
      // collider
      {"collider.shape", {json::object(), "sphere"}},
      {"collider.radius", {{{"shape", "sphere"}}, 0.4}},
      {"collider.tube", {{{"shape", "torus"}, {"radius", 0.2}, {"translate", {0, 0, 0}}}, 0.3}},
      {"collider.height", {{{"shape", "capsule"}, {"rotate", {90, 0, 0}}, {"radius", 0.1}}, 0.1}},
      {"collider.normal", {{{"shape", "plane"}}, json::array({0.3, 1, 0})}},
      {"collider.scale", {json::object(), 1.5}},
      {"collider.file", {{{"shape", "mesh"}, {"file", "data/target_cube.obj"}}, "data/target_tetra.obj"}},
      // solver
      {"solver.colliders", {json::object(), json::array()}},
      // the heap asks for more than a few substeps: a low cap binds
      {"solver.max_substeps", {json::object(), 2}},
      // a tolerance far under the heap's overlaps keeps error control at max_substeps
      {"solver.error_tolerance", {json::object(), 1e-6}},
      // grains
      {"grains.activation", {json::object(), 0}},
      {"grains.group", {json::object(), "nobody"}},
      // a hint for missing pscale and the mass-shock length scale
      {"grains.particle_separation", {{{"enable_mass_shock_scaling", true}}, 0.05}},
      // candidates at exactly the contact distance miss contacts that form during iterations
      {"grains.neighbor_query_scale", {json::object(), 1.0}},
      // mixed radii: searched as the largest, small grains' candidate lists fill with farther
      // grains once max_neighbors caps them
      {"grains.assume_uniform_radius", {{{"max_neighbors", 6}}, true}},
      {"grains.shock_scaling_power", {{{"enable_mass_shock_scaling", true}}, 3}},
      {"grains.shock_axis", {{{"enable_mass_shock_scaling", true}}, json::array({1, 0, 0})}},
      {"grains.shock_origin", {{{"enable_mass_shock_scaling", true}}, json::array({0, 2, 0})}},
      {"grains.mass_shock_method", {{{"enable_mass_shock_scaling", true}}, "local"}},
      {"grains.clumping_stiffness", {{{"clumping_weight", 0.5}}, 1}},
      {"grains.static_threshold", {json::object(), 0.1}},
      {"grains.drift_threshold", {json::object(), 0.5}},
      // sleeping within the scene's 12 frames asks for a short sleep_time; off, the settling grains
      // keep moving
      {"grains.sleep_speed", {{{"sleep_time", 0.1}}, 0}},
      {"grains.sleep_time", {json::object(), 0.1}},
      {"grains.max_speed", {json::object(), 0.5}},
      {"grains.max_acceleration", {json::object(), 5}},
      {"grains.max_neighbors", {json::object(), 2}},
      {"grains.internal_collisions_stiffness", {json::object(), 2}},
      // the Jacobi path's own (refused with the default gauss_seidel)
      {"grains.accurate_friction", {{{"contact_solver", "jacobi"}}, nullptr}},
      {"grains.contact_memory", {{{"contact_solver", "jacobi"}}, nullptr}},
      {"grains.chebyshev_rho", {{{"contact_solver", "jacobi"}}, nullptr}},
      {"grains.update_collisions_during_iterations", {{{"contact_solver", "jacobi"}}, nullptr}},
      {"grains.update_neighbors_during_iterations", {{{"contact_solver", "jacobi"}}, nullptr}},
      {"grains.use_opencl", {json::object(), nullptr}},
      // with gauss_seidel the contacts are not averaged (only explicit constraints and clumping,
      // which the heap has not)
      {"grains.disable_constraint_averaging", {{{"contact_solver", "jacobi"}}, nullptr}},
      // explicit constraints, in the connected-sheet scene
      {"grains.explicit_constraints_weight", {json::object(), nullptr, "grains_constraints"}},
      {"grains.explicit_constraints_stiffness", {json::object(), 2, "grains_constraints"}},
      {"grains.collide_mutually_constrained_particles", {json::object(), nullptr, "grains_constraints"}},
      {"grains.instantaneous_strain", {json::object(), nullptr, "grains_constraints"}},
      {"grains.strain_decay", {{{"instantaneous_strain", false}}, nullptr, "grains_constraints"}},
      {"grains.break_constraints", {json::object(), nullptr, "grains_constraints"}},
      {"grains.break_threshold", {{{"break_constraints", true}}, nullptr, "grains_constraints"}},
      {"grains.remove_strands", {json::object(), nullptr, "grains_constraints"}},
      // source constraints
      {"source.connect_radius", {json::object(), 1.5}},
      {"source.threshold",
       {{{"shape", "image"}, {"file", "data/mask_half.png"}, {"size", {1.9, 0, 0.9}}}, 1.0}},
      // pins: the scene adds a target node when these are authored (see scenes())
      {"grains.target_weight", {{{"target_weight", 1}, {"target_stiffness", 1000}}, 0.3}},
      {"grains.target_stiffness", {{{"target_weight", 1}, {"target_stiffness", 1000}}, 300}},
      // the scene adds a plate of grains joined by edges when this is authored
      {"grains.enable_rigid_shape_matching", {{{"enable_rigid_shape_matching", false}}, true}},
      // target
      {"target.activation", {json::object(), 0}},
      {"target.group", {json::object(), "nobody"}},
      {"target.mode", {{{"file", "data/target_cube.obj"}}, "surface"}},
      {"target.file", {{{"mode", "surface"}, {"file", "data/target_cube.obj"}}, "data/target_tetra.obj"}},
      {"target.pivot", {{{"rotate", {0, 30, 0}}}, json::array({0.3, 0.5, 0.7})}},
  };
}

}  // namespace

TEST_CASE("every parameter of every node type changes the result", "[conformance]") {
  register_builtin_nodes();
  auto sc = scenes();
  auto sp = specials();
  for (const NodeTypeInfo* t : node_types()) {
    if (t->params.empty()) continue;  // merge has none
    INFO("node type " << t->type);
    REQUIRE(sc.count(t->type));
    for (const ParamDecl& d : t->params) {
      std::string key = t->type + "." + d.name;
      INFO("parameter " << key);
      json context = json::object(), value = changed_value(d);
      if (auto it = sp.find(key); it != sp.end()) {
        context = it->second.context;
        if (!it->second.changed.is_null()) value = it->second.changed;
      }
      json changed = context;
      changed[d.name] = value;
      const Scene& scene = sc[sp.count(key) && !sp[key].scene.empty() ? sp[key].scene : t->type];
      Outcome a = run(scene(context), 12);
      Outcome b = run(scene(changed), 12);
      CHECK_FALSE(a == b);
    }
  }
}
