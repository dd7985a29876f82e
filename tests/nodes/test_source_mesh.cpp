// The source's mesh shapes: `surface` scatters grains over a triangle mesh at the separation,
// `volume` fills a closed mesh's inside with the packing; both once or at a rate. Counts are held
// to bounds derived from the mesh's area and volume, positions to the mesh.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "engine/mesh_shape.h"
#include "tests/support/meshes.h"
#include "tests/support/support.h"

using namespace grains;
using json = nlohmann::json;

namespace {

void write_obj_file(const std::string& path, const Mesh& m) { write_obj(path, m); }

// The source with `params` and a solver below it (no forces: grains stay where they are born),
// run `frames` frames in `dir` (the graph's folder).
ParticleStore emit(const json& params, const std::string& dir, int frames = 1) {
  json g = {{"grains_graph", 1},
            {"fps", 24},
            {"frames", frames},
            {"seed", 4},
            {"nodes",
             {{{"name", "src"}, {"type", "source"}, {"params", params}},
              {{"name", "solver"}, {"type", "solver"}, {"inputs", {"src"}}}}}};
  Simulation sim(test::graph_from(g.dump(), dir + "/g.json"), 1);
  for (int f = 0; f < frames; ++f) sim.step_frame();
  return sim.object(0).pts;
}

std::vector<Vec3> positions(const ParticleStore& s) {
  std::vector<Vec3> out;
  for (size_t k = 0; k < s.size(); ++k) out.push_back(load3(s.v3_if("P"), k));
  return out;
}

double mesh_area(const Mesh& m) {
  double a = 0;
  for (const auto& t : m.triangles)
    a += 0.5 * length(cross(m.vertices[t[1]] - m.vertices[t[0]], m.vertices[t[2]] - m.vertices[t[0]]));
  return a;
}

LoadError load_error(const json& params, const std::string& dir) {
  json g = {{"grains_graph", 1},
            {"nodes",
             {{{"name", "src"}, {"type", "source"}, {"params", params}},
              {{"name", "solver"}, {"type", "solver"}, {"inputs", {"src"}}}}}};
  return test::refusal_of(g.dump(), dir + "/g.json");
}

}  // namespace

TEST_CASE("box fill, hexagonal: every grain wholly inside the box, none closer than the separation",
          "[source]") {
  // column_collapse's column: a 0.1 x 0.2 x 0.1 box at 1 cm in a sleeve whose walls touch the
  // box. The offset rows and layers had reached a separation past the box, into the sleeve.
  const float s = 0.01f;
  const Vec3 c{0, 0.1f, 0}, half{0.05f, 0.1f, 0.05f};
  const ParticleStore pts = emit({{"shape", "box"}, {"center", {c.x, c.y, c.z}},
                                  {"size", {2 * half.x, 2 * half.y, 2 * half.z}},
                                  {"separation", s}, {"packing", "hexagonal"}},
                                 test::source_dir() + "/tests");
  const std::vector<Vec3> P = positions(pts);
  // hexagonal close packing: about 0.74 / (4/3 pi (s/2)^3) a unit volume, less the surface's
  double expected = 0.7405 * 8 * half.x * half.y * half.z / (4.0 / 3.0 * M_PI * std::pow(s / 2, 3));
  INFO(P.size() << " grains, " << expected << " at the bulk's density");
  CHECK(P.size() > 0.7 * expected);
  CHECK(P.size() < expected);
  float closest = 1e9f;
  for (size_t a = 0; a < P.size(); ++a) {
    const Vec3 d = P[a] - c;
    CHECK(std::fabs(d.x) + s / 2 <= half.x + 1e-6f);
    CHECK(std::fabs(d.y) + s / 2 <= half.y + 1e-6f);
    CHECK(std::fabs(d.z) + s / 2 <= half.z + 1e-6f);
    for (size_t b = a + 1; b < P.size(); ++b) closest = std::min(closest, length(P[b] - P[a]));
  }
  CHECK(closest == Approx(s).epsilon(1e-4));
}

TEST_CASE("volume fill: the packing inside a closed mesh, every grain wholly inside",
          "[mesh][source]") {
  const std::string dir = test::temp_dir("source_volume");
  SECTION("a box: exactly the lattice points a radius inside its faces") {
    // The 0.3 m cube's bounding-box lattice at 0.05 m runs -0.15 .. 0.15 (7 a side); a grain of
    // radius 0.025 is wholly inside where |x|, |y|, |z| <= 0.125: 5 a side, 125.
    write_obj_file(dir + "/cube.obj", test::box_mesh({0, 0, 0}, {0.3f, 0.3f, 0.3f}));
    const ParticleStore s = emit({{"shape", "volume"}, {"file", "cube.obj"}, {"separation", 0.05},
                                  {"center", {1, 2, 3}}},
                                 dir);
    CHECK(s.size() == 125);
    for (const Vec3& p : positions(s)) {
      CHECK(std::fabs(p.x - 1) <= 0.125f + 1e-5f);
      CHECK(std::fabs(p.y - 2) <= 0.125f + 1e-5f);
      CHECK(std::fabs(p.z - 3) <= 0.125f + 1e-5f);
    }
  }
  SECTION("a sphere: the count within the lattice's bounds for its volume") {
    // Inside = at least r = s/2 within the faceted sphere, which lies between the balls of
    // radius R - sagitta and R. Each kept point owns its lattice cell (volume C, every point of
    // it within h = sqrt(3) s / 2), so N C <= V(R - r + h); every point of the ball of radius
    // R - sagitta - r - h lies in the cell of a kept point, so N C >= V(R - sagitta - r - h).
    const float R = 0.3f, s = 0.03f, r = s / 2, h = std::sqrt(3.0f) * s / 2;
    const Mesh m = test::sphere_mesh({0, 0, 0}, R, 3);
    write_obj_file(dir + "/ball.obj", m);
    std::string problem;
    const auto shape = MeshShape::build(m, &problem);
    float longest = 0;
    for (const auto& t : m.triangles)
      for (int k = 0; k < 3; ++k)
        longest = std::max(longest, length(m.vertices[t[k]] - m.vertices[t[(k + 1) % 3]]));
    const float sagitta = R - std::sqrt(R * R - longest * longest / 3);
    for (const char* packing : {"grid", "hexagonal"}) {
      const ParticleStore st =
          emit({{"shape", "volume"}, {"file", "ball.obj"}, {"separation", s}, {"packing", packing}},
               dir);
      auto ball = [](double radius) { return 4.0 / 3.0 * M_PI * radius * radius * radius; };
      // each point's Voronoi cell: the cube s^3, or hexagonal packing's s^3 / sqrt(2) (its
      // farthest corner s / sqrt(2) away, within h too)
      const double cell = std::string(packing) == "grid" ? s * s * s : s * s * s / std::sqrt(2.0);
      INFO(packing << ": " << st.size() << " grains");
      CHECK(double(st.size()) <= ball(R - r + h) / cell);
      CHECK(double(st.size()) >= ball(R - sagitta - r - h) / cell);
      for (const Vec3& p : positions(st)) CHECK(shape->distance(p, nullptr) <= -r + 1e-6f);
    }
  }
  SECTION("an open mesh cannot be filled") {
    Mesh cup = test::box_mesh({0, 0, 0}, {1, 1, 1});
    cup.triangles.resize(10);
    write_obj_file(dir + "/cup.obj", cup);
    const LoadError e = load_error({{"shape", "volume"}, {"file", "cup.obj"}}, dir);
    CHECK(e.pointer == "/nodes/0/params/file");
    CHECK(std::string(e.what()).find("closed mesh") != std::string::npos);
  }
}

TEST_CASE("surface scatter: grains on the mesh, none closer than the separation", "[mesh][source]") {
  // On the sphere mesh (area A), no two grains closer than s, each on a triangle. No such set
  // holds more than hexagonal packing's 2 A / (sqrt(3) s^2); one that leaves no room for another
  // covers the surface with discs of radius s, so holds at least A / (pi s^2).
  const std::string dir = test::temp_dir("source_surface");
  const Mesh m = test::sphere_mesh({0, 0, 0}, 0.3f, 3);
  write_obj_file(dir + "/ball.obj", m);
  std::string problem;
  const auto shape = MeshShape::build(m, &problem);
  const float s = 0.03f;
  const double A = mesh_area(m);
  const ParticleStore st =
      emit({{"shape", "surface"}, {"file", "ball.obj"}, {"separation", s}, {"center", {0, 1, 0}}}, dir);
  const std::vector<Vec3> p = positions(st);
  INFO(p.size() << " grains on " << A << " m^2");
  CHECK(double(p.size()) <= 2 * A / (std::sqrt(3.0) * s * s));
  CHECK(double(p.size()) >= A / (M_PI * s * s));
  float closest = 1e30f;
  for (size_t i = 0; i < p.size(); ++i) {
    CHECK(std::fabs(shape->distance(p[i] - Vec3{0, 1, 0}, nullptr)) < 1e-5f);
    for (size_t j = i + 1; j < p.size(); ++j) closest = std::min(closest, length(p[i] - p[j]));
  }
  CHECK(closest >= s * (1 - 1e-5f));
  // the same graph, the same grains
  const ParticleStore again =
      emit({{"shape", "surface"}, {"file", "ball.obj"}, {"separation", s}, {"center", {0, 1, 0}}}, dir);
  const std::vector<Vec3> q = positions(again);
  REQUIRE(q.size() == p.size());
  for (size_t i = 0; i < p.size(); ++i) CHECK(length(q[i] - p[i]) == 0.0f);
}

TEST_CASE("mesh shapes emit at a rate: on the surface, or wholly inside", "[mesh][source]") {
  const std::string dir = test::temp_dir("source_mesh_rate");
  const Mesh m = test::sphere_mesh({0, 0, 0}, 0.3f, 2);
  write_obj_file(dir + "/ball.obj", m);
  std::string problem;
  const auto shape = MeshShape::build(m, &problem);
  for (const char* kind : {"surface", "volume"}) {
    // 240 grains a second for 12 frames: 120
    const ParticleStore st = emit({{"shape", kind}, {"file", "ball.obj"}, {"emission", "rate"},
                                   {"rate", 240}, {"separation", 0.02}},
                                  dir, 12);
    INFO(kind);
    CHECK(st.size() == 120);
    Vec3 mean{0, 0, 0};
    for (const Vec3& p : positions(st)) {
      const float d = shape->distance(p, nullptr);
      if (std::string(kind) == "surface") CHECK(std::fabs(d) < 1e-5f);
      else CHECK(d <= -0.01f + 1e-6f);
      mean += p / 120.0f;
    }
    // spread over the whole mesh: the mean within a tenth of the radius of its centre
    CHECK(length(mean) < 0.03f);
  }
}

TEST_CASE("mesh shapes without a usable mesh are refused at load", "[mesh][source]") {
  const std::string dir = test::temp_dir("source_mesh_bad");
  test::write_file(dir, "points.obj", "v 0 0 0\nv 1 0 0\n");
  for (const char* kind : {"surface", "volume"}) {
    INFO(kind);
    LoadError e = load_error({{"shape", kind}}, dir);
    CHECK(e.pointer == "/nodes/0/params/file");
    CHECK(std::string(e.what()).find("needs a mesh `file`") != std::string::npos);
    e = load_error({{"shape", kind}, {"file", "none.obj"}}, dir);
    CHECK(std::string(e.what()).find("none.obj") != std::string::npos);
    e = load_error({{"shape", kind}, {"file", "points.obj"}}, dir);
    CHECK(std::string(e.what()).find("no triangles") != std::string::npos);
  }
}
