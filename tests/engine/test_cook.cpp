// Cooking one node in isolation (DESIGN §5): cook_node() and `grains cook`.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>

#include "engine/cook.h"
#include "engine/geometry_io.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;
namespace fs = std::filesystem;

namespace {

ParticleStore points(std::initializer_list<Vec3> ps, float pscale = 0.05f) {
  ParticleStore s;
  s.add_points(ps.size());
  size_t k = 0;
  for (const Vec3& p : ps) {
    store3(s.v3("P"), k, p);
    s.f("pscale")[k] = pscale;
    ++k;
  }
  return s;
}

}  // namespace

TEST_CASE("cooking force on one point reproduces free fall", "[cook]") {
  // unit mass, force -9.81 N for 1 s in 24 frames of 3 substeps: the solver integrates a constant
  // force exactly, so y = -g t^2 / 2 to float rounding.
  register_builtin_nodes();
  ParticleStore s = points({{0, 0, 0}});
  CookOptions o;
  o.substeps = 3;
  o.frames = 24;
  cook_node("force", {{"force", "[0, -9.81, 0]"}}, s, o);
  CHECK(load3(s.v3("P"), 0).y == Approx(-0.5 * 9.81).epsilon(1e-5));
  CHECK(load3(s.v3("v"), 0).y == Approx(-9.81).epsilon(1e-5));
}

TEST_CASE("cooking grains on two overlapping points separates them to contact", "[cook]") {
  // Two grains of radius 0.05 at 0.06 apart overlap by 0.04. With stiffness above
  // substeps x iterations each iteration removes the whole overlap, shared by equal masses,
  // so after one substep they sit at 2r within float rounding.
  register_builtin_nodes();
  ParticleStore s = points({{0, 0, 0}, {0.06f, 0, 0}});
  cook_node("grains", {{"constraint_iterations", "10"}, {"friction_with_particles", "0"}}, s, 1);
  Vec3 a = load3(s.v3("P"), 0), b = load3(s.v3("P"), 1);
  CHECK(length(b - a) == Approx(0.1).epsilon(1e-4));
  CHECK(a.x + b.x == Approx(0.06).epsilon(1e-4));  // momentum: the midpoint stays
  CHECK(s.i("ispbd")[0] == 1);
}

TEST_CASE("cooking group writes the group into the output", "[cook]") {
  std::string dir = temp_dir("cook_group");
  ParticleStore s = points({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}});
  write_ply(dir + "/in.ply", s, {});
  REQUIRE(run_grains("cook group --in " + dir + "/in.ply --set group_name=near --set rule=sphere "
                     "--set radius=1.5 --out " + dir + "/out",
                     dir + "/log") == 0);
  ParticleStore out = read_ply(dir + "/out/frame_0001.ply");
  REQUIRE(out.has("group_near"));
  CHECK(out.i_if("group_near")[0] == 1);
  CHECK(out.i_if("group_near")[1] == 1);
  CHECK(out.i_if("group_near")[2] == 0);
  CHECK(fs::exists(dir + "/out/stats.csv"));
}

TEST_CASE("a cooked node equals the same node inside a one-node graph", "[cook]") {
  // the same points, once through `grains cook`, once as a graph whose source reads the file
  std::string dir = temp_dir("cook_same");
  ParticleStore s;
  s.add_points(60);
  for (size_t k = 0; k < 60; ++k) {
    store3(s.v3("P"), k, Vec3(0.09f * (k % 4), 0.051f + 0.09f * (k / 16), 0.09f * ((k / 4) % 4)));
    store3(s.v3("v"), k, Vec3(0.1f * (k % 3), 0, 0));
    s.f("pscale")[k] = 0.05f;
  }
  write_ply(dir + "/in.ply", s, {"mass"});
  REQUIRE(run_grains("cook grains --in " + dir + "/in.ply --substeps 2 --frames 3 --ground 0 "
                     "--set constraint_iterations=15 --out " + dir + "/cooked",
                     dir + "/log") == 0);
  std::string graph = write_file(dir, "one.json", R"({"grains_graph": 1, "fps": 24, "frames": 3, "nodes": [
    {"name": "in", "type": "source", "params": {"shape": "file", "file": "in.ply"}},
    {"name": "node", "type": "grains", "inputs": ["in"], "params": {"constraint_iterations": 15}},
    {"name": "ground", "type": "collider", "params": {"shape": "plane"}},
    {"name": "solver", "type": "solver", "inputs": ["node"], "params": {"substeps": 2, "error_control": false, "colliders": ["ground"]}}]})");
  REQUIRE(run_grains("run " + graph + " --quiet --out " + dir + "/graph", dir + "/log2") == 0);
  for (int f = 1; f <= 3; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "/frame_%04d.ply", f);
    ParticleStore a = read_ply(dir + "/cooked" + name), b = read_ply(dir + "/graph" + name);
    REQUIRE(a.size() == b.size());
    CHECK(a.find("P")->f == b.find("P")->f);  // bit-identical
    CHECK(a.find("v")->f == b.find("v")->f);
  }
}

TEST_CASE("cook refuses bad input with exit code 2", "[cook]") {
  std::string dir = temp_dir("cook_bad");
  ParticleStore s = points({{0, 0, 0}});
  write_ply(dir + "/in.ply", s, {});
  auto cook = [&](const std::string& args) {
    return run_grains("cook " + args + " --out " + dir + "/o", dir + "/log");
  };
  CHECK(cook("nosuch --in " + dir + "/in.ply") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("unknown node type 'nosuch'"));
  CHECK(cook("solver --in " + dir + "/in.ply") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("does not act on particles"));
  CHECK(cook("grains --in " + dir + "/in.ply --set frictoin=1") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("--set frictoin"));
  CHECK(cook("grains --in " + dir + "/in.ply --set constraint_iterations=abc") == 2);
  CHECK(cook("grains --in " + dir + "/missing.ply") == 2);
  write_file(dir, "nopos.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n1\n");
  CHECK(cook("grains --in " + dir + "/nopos.ply") == 2);
  write_file(dir, "intscale.ply",
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
             "property float z\nproperty int pscale\nend_header\n0 0 0 1\n");
  CHECK(cook("grains --in " + dir + "/intscale.ply") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("pscale"));
}
