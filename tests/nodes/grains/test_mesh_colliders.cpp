// Grains against triangle-mesh colliders (engine/mesh_shape.h) through the whole substep: a mesh
// box holds a pile where the analytic box does, fast grains never pass a closed mesh or a sheet,
// and a turning mesh carries the grains on it.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include "engine/mesh_shape.h"
#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/meshes.h"

using namespace grains;
using namespace grains::test;

namespace {

ColliderState mesh_collider(const Mesh& m, const Pose& pose = Pose{}) {
  ColliderState c;
  c.name = "mesh";
  c.shape.kind = ShapeKind::Mesh;
  std::string problem;
  c.shape.mesh = MeshShape::build(m, &problem);
  REQUIRE(c.shape.mesh);
  c.pose = c.prev_pose = pose;
  return c;
}

// A 5 x 5 x 3 block of grains of radius r, spacing 2r, its lowest layer at height y0.
void add_block(Scene& sc, float r, float y0) {
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 5; ++k)
        sc.add({(i - 2) * 2 * r + 0.1f * r * j, y0 + j * 2 * r, (k - 2) * 2 * r - 0.1f * r * j}, r);
}

// Every grain of sc, all of radius r, started on side `side` (+1 above, -1 below) of a slab or
// sheet in the plane y = 0: each must end on that side, at least r from the surface (less the
// trace's tolerance, 1e-3 r).
void check_kept_side(const Scene& sc, const ColliderState& c, float side, float r,
                     const std::string& what) {
  int crossed = 0;
  float nearest = 1e30f;
  for (size_t i = 0; i < sc.size(); ++i) {
    if (sc.pos(i).y * side < 0) ++crossed;
    nearest = std::min(nearest, c.distance(sc.pos(i), nullptr));
  }
  INFO(what << ", from " << (side > 0 ? "above" : "below"));
  report((what + ": nearest / r").c_str(), nearest / r);
  CHECK(crossed == 0);
  CHECK(nearest > r * (1 - 1e-3f));
}

}  // namespace

TEST_CASE("a block of grains settles on a mesh box as on the analytic box", "[mesh][colliders][grains]") {
  // The same box as 12 triangles and as the analytic shape, tilted 10 degrees and lifted. The
  // two shapes' distances agree to float rounding (test_mesh_shape.cpp), so the grains meet the
  // same contact planes: after 1.5 s every grain ends within 1% of its radius of its place on
  // the analytic box, and the pile stands on the box (lowest grain one radius above the top).
  const float r = 0.05f;
  const Vec3 size{1.2f, 0.2f, 1.2f};
  const Pose pose = Pose::from_trs({0.1f, 0.4f, -0.05f}, {0, 20, 10}, 1.0f);
  std::vector<Vec3> ends[2];
  for (int mesh = 0; mesh < 2; ++mesh) {
    Scene sc;
    sc.s = settings(24, 4, 20);
    ColliderState c = mesh ? mesh_collider(box_mesh({0, 0, 0}, size), pose) : box({0, 0, 0}, size);
    c.pose = c.prev_pose = pose;
    sc.add_collider(c);
    add_block(sc, r, 0.7f);
    sc.run(1.5f);
    for (size_t i = 0; i < sc.size(); ++i) ends[mesh].push_back(sc.pos(i));
    float lowest = 1e30f;
    for (size_t i = 0; i < sc.size(); ++i) lowest = std::min(lowest, c.distance(sc.pos(i), nullptr));
    report(mesh ? "mesh box: lowest grain's distance / r" : "analytic box: lowest grain's distance / r",
           lowest / r);
    CHECK(lowest > 0.95f * r);
  }
  float worst = 0;
  for (size_t i = 0; i < ends[0].size(); ++i) worst = std::max(worst, length(ends[0][i] - ends[1][i]));
  report("mesh vs analytic box: largest difference / r", worst / r);
  CHECK(worst < 0.01f * r);
}

TEST_CASE("no grain passes a closed mesh or a sheet at 10 m/s", "[mesh][colliders][grains]") {
  // At 24 fps and 10 substeps a 10 m/s grain moves 4.2 cm a substep, four times the slab's
  // 1 cm: only the final collision pass's sweep sees it cross. Grains come from every direction
  // of the front half-space; every one must end on its own side, at least its radius from the
  // surface (less the trace's tolerance, 1e-3 r). The sheet (an open mesh) must hold from both
  // sides.
  const float r = 0.02f;
  struct Case {
    const char* name;
    Mesh mesh;
  };
  const Case cases[] = {{"closed slab", box_mesh({0, 0, 0}, {2, 0.01f, 2})},
                        {"open sheet", quad_mesh(1.0f)}};
  for (const Case& cs : cases)
    for (float side : {1.0f, -1.0f}) {
      Scene sc;
      sc.s = settings(24, 10, 10);
      sc.gravity = {0, 0, 0};
      const ColliderState c = mesh_collider(cs.mesh);
      sc.add_collider(c);
      std::mt19937 rng(11);
      std::uniform_real_distribution<float> u(-1, 1);
      const int n = 60;
      for (int k = 0; k < n; ++k) {
        // start 0.3 m away on this side, aimed at a point of the slab near the centre
        Vec3 dir{u(rng), -side * (0.3f + 0.7f * std::fabs(u(rng))), u(rng)};
        dir = normalized(dir);
        const Vec3 aim{0.4f * u(rng), 0, 0.4f * u(rng)};
        sc.add(aim - dir * 0.3f, r, 1, dir * 10.0f);
      }
      sc.run(0.25f);
      check_kept_side(sc, c, side, r, cs.name);
    }
}

TEST_CASE("a turning mesh carries the grains on it", "[mesh][colliders][grains]") {
  // A turntable of triangles (a 2 m x 0.1 m x 2 m box) turning about y at w = 2 rad/s, eight
  // grains on it 0.4 m from the axis. Static friction holds them: the centripetal acceleration
  // w^2 R = 1.6 m/s^2 is below mu g = 0.5 x 9.81 (collider friction 1 x the help page's
  // static threshold). After 2 s (0.64 turns) each grain moves with the table: speed w R =
  // 0.8 m/s within 5%, still 0.4 m from the axis within a radius, resting on top.
  const float w = 2.0f, R = 0.4f, r = 0.05f;
  Scene sc;
  sc.s = settings(24, 10, 10);
  sc.s.friction_with_colliders = 1.0f;
  sc.add_collider(mesh_collider(box_mesh({0, -0.05f, 0}, {2, 0.1f, 2})), [&](float t) {
    return Pose::from_trs({0, 0, 0}, {0, w * t * 180.0f / float(M_PI), 0}, 1.0f);
  });
  for (int k = 0; k < 8; ++k) {
    const float a = float(k) * float(M_PI) / 4;
    sc.add({R * std::cos(a), r, R * std::sin(a)}, r);
  }
  sc.run(2.0f);
  for (size_t i = 0; i < sc.size(); ++i) {
    const Vec3 p = sc.pos(i), v = sc.vel(i);
    const float radial = std::sqrt(p.x * p.x + p.z * p.z);
    const float speed = std::sqrt(v.x * v.x + v.z * v.z);
    INFO("grain " << i);
    report("turntable: grain speed / (w R)", speed / (w * R));
    CHECK(speed == Approx(w * R).epsilon(0.05));
    CHECK(std::fabs(radial - R) < r);
    CHECK(p.y == Approx(r).margin(0.1f * r));
  }
}

TEST_CASE("a grain pressed through a sheet from within half its radius is put back", "[mesh][colliders][grains]") {
  // A grain that starts a substep within r/2 of a sheet is inside the sweep's hit distance from
  // the start, so the sweep cannot say where it first came near; a sheet has no inside, so its
  // distance cannot say which side the grain ends on. A grain there driven at 10 m/s into the
  // sheet (4.2 cm a substep, twice its radius: what a heavy pile's pressure does to one grain
  // in a substep at worst) ends past the sheet by more than its radius unless the pass sees its
  // path cross the triangles. Every grain must end on the side it started, at least r away.
  const float r = 0.02f;
  for (float side : {1.0f, -1.0f}) {
    Scene sc;
    sc.s = settings(24, 10, 10);
    sc.gravity = {0, 0, 0};
    const ColliderState c = mesh_collider(quad_mesh(1.0f));
    sc.add_collider(c);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1, 1);
    for (int k = 0; k < 40; ++k) {
      // 0.1 r to 0.45 r from the sheet
      const Vec3 p{0.8f * u(rng), side * r * (0.275f + 0.175f * u(rng)), 0.8f * u(rng)};
      sc.add(p, r, 1, Vec3{u(rng), -side * 10.0f, u(rng)});
    }
    sc.run(0.1f);
    check_kept_side(sc, c, side, r, "sheet, started within r/2");
  }
}
