// The collider node's `mesh` shape: OBJ and PLY files relative to the graph, the same result as
// the analytic shape they describe, the triangles written beside the run's poses for the viewer,
// and clear refusals of missing or unusable files.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "engine/collider_poses.h"
#include "engine/mesh_shape.h"
#include "tests/support/meshes.h"
#include "tests/support/support.h"

using namespace grains;
using json = nlohmann::json;

namespace {

// A 4 x 2 x 4 block of grains (separation 0.05) dropped on `floor`, one thread, `frames` frames.
json drop_graph(const json& floor, int frames = 24) {
  return {{"grains_graph", 1},
          {"fps", 24},
          {"frames", frames},
          {"seed", 1},
          {"nodes",
           {{{"name", "src"},
             {"type", "source"},
             {"params",
              {{"shape", "box"}, {"size", {0.2, 0.1, 0.2}}, {"center", {0, 0.5, 0}},
               {"separation", 0.05}}}},
            {{"name", "gravity"},
             {"type", "force"},
             {"inputs", {"src"}},
             {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}},
            {{"name", "grains"},
             {"type", "grains"},
             {"inputs", {"gravity"}},
             {"params", {{"particle_separation", 0.05}}}},
            {{"name", "floor"}, {"type", "collider"}, {"params", floor}},
            {{"name", "solver"},
             {"type", "solver"},
             {"inputs", {"grains"}},
             {"params", {{"colliders", {"floor"}}}}}}}};
}

std::vector<Vec3> run_positions(const json& g, const std::string& dir) {
  Simulation sim(test::graph_from(g.dump(), dir + "/g.json"), 1);
  for (int f = 0; f < g["frames"].get<int>(); ++f) sim.step_frame();
  const ParticleStore& s = sim.object(0).pts;
  const float* P = s.v3_if("P");
  std::vector<Vec3> out;
  for (size_t k = 0; k < s.size(); ++k) out.push_back({P[3 * k], P[3 * k + 1], P[3 * k + 2]});
  return out;
}

std::string obj_text(const Mesh& m) {
  std::string t = "# a box\n";
  for (const Vec3& v : m.vertices)
    t += "v " + std::to_string(v.x) + " " + std::to_string(v.y) + " " + std::to_string(v.z) + "\n";
  for (const auto& f : m.triangles)
    t += "f " + std::to_string(f[0] + 1) + " " + std::to_string(f[1] + 1) + " " +
         std::to_string(f[2] + 1) + "\n";
  return t;
}

std::string ply_text(const Mesh& m) {
  std::string t = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(m.vertices.size()) +
                  "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                  std::to_string(m.triangles.size()) +
                  "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const Vec3& v : m.vertices)
    t += std::to_string(v.x) + " " + std::to_string(v.y) + " " + std::to_string(v.z) + "\n";
  for (const auto& f : m.triangles)
    t += "3 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + "\n";
  return t;
}

LoadError load_error(const json& g, const std::string& dir) {
  return test::refusal_of(g.dump(), dir + "/g.json");
}

}  // namespace

TEST_CASE("a mesh collider from an OBJ or PLY file holds grains where the box does",
          "[mesh][colliders][collider]") {
  // The box [1, 0.2, 1] as triangles in its local frame; the collider node places both the same
  // way (tilted 5 degrees about z, lifted 0.1 m). Distances agree to float rounding
  // (test_mesh_shape.cpp), so each grain ends within 1% of its radius (0.025 m) of its place on
  // the analytic box.
  const std::string dir = test::temp_dir("mesh_node");
  const Mesh m = test::box_mesh({0, 0, 0}, {1, 0.2f, 1});
  test::write_file(dir, "box.obj", obj_text(m));
  std::filesystem::create_directories(dir + "/meshes");
  test::write_file(dir + "/meshes", "box.ply", ply_text(m));
  const json pose = {{"translate", {0, 0.1, 0}}, {"rotate", {0, 0, 5}}};
  json box = pose, from_obj = pose, from_ply = pose;
  box.update({{"shape", "box"}, {"size", {1, 0.2, 1}}});
  from_obj.update({{"shape", "mesh"}, {"file", "box.obj"}});
  from_ply.update({{"shape", "mesh"}, {"file", "meshes/box.ply"}});
  const auto want = run_positions(drop_graph(box), dir);
  REQUIRE(want.size() == 32);
  for (const json& floor : {from_obj, from_ply}) {
    const auto got = run_positions(drop_graph(floor), dir);
    REQUIRE(got.size() == want.size());
    float worst = 0;
    for (size_t k = 0; k < got.size(); ++k) worst = std::max(worst, length(got[k] - want[k]));
    INFO(floor["file"]);
    CHECK(worst < 0.01f * 0.025f);
    // and they rest on it, not where they started
    for (const Vec3& p : got) CHECK(p.y < 0.45f);
  }
}

TEST_CASE("a run writes a mesh collider's triangles beside its poses, and the viewer draws it",
          "[mesh][colliders][collider][viewer]") {
  const std::string dir = test::temp_dir("mesh_run");
  test::write_file(dir, "ball.obj", [] {
    const Mesh m = test::sphere_mesh({0, 0, 0}, 0.3f, 2);
    return obj_text(m);
  }());
  json g = drop_graph({{"shape", "mesh"}, {"file", "ball.obj"}, {"translate", {0, "0.1 * $T", 0}}}, 3);
  const std::string graph = test::write_file(dir, "g.json", g.dump());
  const std::string log = dir + "/log.txt";
  REQUIRE(test::run_grains("run " + graph + " --out " + dir + "/sim --quiet", log) == 0);
  const std::string obj = dir + "/sim/" + collider_mesh_file("floor");
  REQUIRE(std::filesystem::exists(obj));
  const auto frames = read_collider_poses(dir + "/sim/" + kColliderPosesFile);
  REQUIRE(frames.size() == 3);
  const ColliderState& c = frames.at(3)[0];
  REQUIRE(c.shape.kind == ShapeKind::Mesh);
  REQUIRE(c.shape.mesh);
  CHECK(c.shape.mesh->closed());
  // the file's mesh is the one the run measured: the same distance at the same local points
  std::string problem;
  const auto original = MeshShape::build(read_mesh(dir + "/ball.obj"), &problem);
  for (const Vec3& p : {Vec3{0, 0.5f, 0}, Vec3{0.1f, 0.05f, -0.2f}, Vec3{0.4f, -0.3f, 0.1f}})
    CHECK(c.shape.mesh->distance(p, nullptr) == original->distance(p, nullptr));
  CHECK(c.pose.t.y == Approx(0.1f * 3 / 24.0f));
  CHECK(test::run_grains("render " + dir + "/sim --graph " + graph + " --out " + dir +
                             "/pictures --size 96x64",
                         log) == 0);
  INFO(test::read_text(log));
  CHECK(test::read_text(log).find("warning") == std::string::npos);
  CHECK(std::filesystem::exists(dir + "/pictures/frame_0003.png"));
  // a poses file whose mesh is gone is refused with the file's name
  std::filesystem::remove(obj);
  try {
    read_collider_poses(dir + "/sim/" + kColliderPosesFile);
    FAIL("read without its mesh");
  } catch (const GeometryError& e) {
    CHECK(std::string(e.what()).find(collider_mesh_file("floor")) != std::string::npos);
  }
}

TEST_CASE("a mesh collider without a usable file is refused at load", "[mesh][colliders][collider]") {
  const std::string dir = test::temp_dir("mesh_bad");
  test::write_file(dir, "points.ply",
                   "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                   "property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n");
  test::write_file(dir, "broken.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\n");
  const struct {
    json params;
    const char* says;
  } cases[] = {
      {{{"shape", "mesh"}}, "needs a `file`"},
      {{{"shape", "mesh"}, {"file", "missing.obj"}}, "missing.obj"},
      {{{"shape", "mesh"}, {"file", "points.ply"}}, "no triangles"},
      {{{"shape", "mesh"}, {"file", "broken.obj"}}, "out of range"},
      {{{"shape", "mesh"}, {"file", "g.json"}}, "unsupported mesh format"},
  };
  for (const auto& c : cases) {
    const LoadError e = load_error(drop_graph(c.params), dir);
    INFO(e.what());
    CHECK(e.pointer == "/nodes/3/params/file");
    CHECK(std::string(e.what()).find(c.says) != std::string::npos);
  }
}
