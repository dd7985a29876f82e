// Mesh collider shapes (engine/mesh_shape.h): the exact distance of a closed mesh agrees with the
// analytic shape it tessellates; a shell is two-sided; inward winding, split seams and bad meshes.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include "engine/collider.h"
#include "engine/mesh_shape.h"
#include "tests/support/meshes.h"

using namespace grains;

namespace {

std::shared_ptr<const MeshShape> build(const Mesh& m) {
  std::string problem;
  auto s = MeshShape::build(m, &problem);
  INFO(problem);
  REQUIRE(s);
  return s;
}

Shape analytic_box(const Vec3& size) {
  Shape s;
  s.kind = ShapeKind::Box;
  s.size = size;
  return s;
}

}  // namespace

TEST_CASE("a closed mesh box measures the analytic box's signed distance and normal",
          "[mesh][colliders]") {
  // The box's signed distance is piecewise exact for both: outside, the Euclidean distance to
  // the nearest face, edge or corner; inside, minus the distance to the nearest face. Both are
  // computed from the same float corners, so they agree to float rounding (1e-6 m at 1 m).
  // Normals agree wherever the nearest feature is unique: inside points nearly equidistant
  // from two faces (the box's medial surfaces) are skipped.
  const Vec3 size{0.6f, 0.4f, 0.8f};
  const Shape box = analytic_box(size);
  for (bool split : {false, true}) {
    const auto mesh = build(test::box_mesh({0, 0, 0}, size, split));
    CHECK(mesh->closed());
    CHECK(mesh->mesh().vertices.size() == 8);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-0.8f, 0.8f);
    int compared = 0, normals = 0;
    for (int k = 0; k < 4000; ++k) {
      const Vec3 p{u(rng), u(rng), u(rng)};
      Vec3 na, nm;
      const float da = shape_distance(box, p, &na);
      const float dm = mesh->distance(p, &nm);
      INFO("point " << p.x << " " << p.y << " " << p.z);
      REQUIRE(dm == Approx(da).margin(2e-6));
      ++compared;
      // the second-nearest face's distance: a unique nearest face inside when it is well apart
      const Vec3 h = size * 0.5f;
      float gaps[3] = {h.x - std::fabs(p.x), h.y - std::fabs(p.y), h.z - std::fabs(p.z)};
      std::sort(gaps, gaps + 3);
      if (da < 0 && gaps[1] - gaps[0] < 1e-3f) continue;
      CHECK(dot(na, nm) > 0.9999f);
      ++normals;
    }
    CHECK(compared == 4000);
    CHECK(normals > 3500);
  }
}

TEST_CASE("a closed mesh wound inward is turned outward", "[mesh][colliders]") {
  Mesh m = test::box_mesh({0, 0, 0}, {1, 1, 1});
  for (auto& t : m.triangles) std::swap(t[1], t[2]);
  const auto mesh = build(m);
  CHECK(mesh->closed());
  Vec3 n;
  CHECK(mesh->distance({0, 0, 0}, &n) == Approx(-0.5f));
  CHECK(mesh->distance({0, 2, 0}, &n) == Approx(1.5f));
  CHECK(n.y == Approx(1.0f));
}

TEST_CASE("a mesh sphere lies within its chord error of the analytic sphere", "[mesh][colliders]") {
  // Vertices on the sphere of radius R: the mesh lies inside the sphere and contains the ball
  // of radius R - s, where s = R - sqrt(R^2 - e^2 / 3) is the sagitta of a face whose longest
  // edge is e (nearly equilateral faces: circumradius e / sqrt(3)). So the mesh's signed distance
  // lies between the two balls', |p| - R and |p| - R + s, everywhere.
  const float R = 0.5f;
  const Mesh m = test::sphere_mesh({0, 0, 0}, R, 3);
  const auto mesh = build(m);
  CHECK(mesh->closed());
  float longest = 0;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k)
      longest = std::max(longest, length(m.vertices[t[k]] - m.vertices[t[(k + 1) % 3]]));
  const float sagitta = R - std::sqrt(R * R - longest * longest / 3);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1, 1);
  for (int k = 0; k < 2000; ++k) {
    const Vec3 p{u(rng), u(rng), u(rng)};
    Vec3 n;
    const float d = mesh->distance(p, &n);
    INFO("point " << p.x << " " << p.y << " " << p.z);
    CHECK(d >= length(p) - R - 1e-6f);
    CHECK(d <= length(p) - R + sagitta + 1e-6f);
    if (std::fabs(d) > 2 * sagitta) CHECK(dot(n, normalized(p)) > 0.9f);
  }
  CHECK(mesh->distance({0, 0, 0}, nullptr) < -R + sagitta + 1e-6f);
}

TEST_CASE("an open mesh is a two-sided shell", "[mesh][colliders]") {
  const auto sheet = build(test::quad_mesh(1.0f));
  CHECK_FALSE(sheet->closed());
  Vec3 n;
  CHECK(sheet->distance({0.2f, 0.3f, 0}, &n) == Approx(0.3f));
  CHECK(n.y == Approx(1.0f));
  CHECK(sheet->distance({0.2f, -0.3f, 0}, &n) == Approx(0.3f));
  CHECK(n.y == Approx(-1.0f));
  // past the rim: the distance to the edge, pointing away from it
  CHECK(sheet->distance({1.3f, 0.4f, 0}, &n) == Approx(0.5f));
  CHECK(n.x == Approx(0.6f));
  CHECK(n.y == Approx(0.8f));
  // a box with one face missing is open too
  Mesh cup = test::box_mesh({0, 0, 0}, {1, 1, 1});
  cup.triangles.resize(10);
  CHECK_FALSE(build(cup)->closed());
}

TEST_CASE("a segment through a shell finds its first crossing", "[mesh][colliders]") {
  // A segment down through a sheet crosses it where y = 0; one that passes beside it or stops
  // short crosses nothing.
  const auto open = build(test::quad_mesh(1.0f));
  Vec3 n;
  CHECK(open->crossing({0.2f, 0.3f, 0.1f}, {0.2f, -0.1f, 0.1f}, &n) == Approx(0.75f));
  CHECK(std::fabs(n.y) == Approx(1.0f));
  CHECK(open->crossing({0.2f, 0.3f, 0.1f}, {0.2f, 0.01f, 0.1f}, &n) > 1.0f);  // stops short
  CHECK(open->crossing({1.2f, 0.3f, 0.1f}, {1.2f, -0.3f, 0.1f}, &n) > 1.0f);  // beside the sheet
  CHECK(open->crossing({-2, 0.5f, 0}, {2, -0.5f, 0}, &n) == Approx(0.5f));   // long and slanted
  CHECK(open->crossing({0.2f, 0, 0.1f}, {0.2f, -0.3f, 0.1f}, &n) > 1.0f);  // starts on it: no side
  CHECK(open->crossing({0.2f, 0.3f, 0.1f}, {0.2f, 0, 0.1f}, &n) == Approx(1.0f));  // ends on it
  // through two walls of a box: the first one counts
  const auto box = build(test::box_mesh({0, 0, 0}, {1, 1, 1}));
  CHECK(box->crossing({-1, 0.1f, 0.2f}, {1, 0.1f, 0.2f}, &n) == Approx(0.25f));
  CHECK(std::fabs(n.x) == Approx(1.0f));
}

TEST_CASE("a mesh without usable triangles is refused", "[mesh][colliders]") {
  std::string problem;
  Mesh points;
  points.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  CHECK_FALSE(MeshShape::build(points, &problem));
  CHECK(problem.find("no triangles") != std::string::npos);
  Mesh flat = points;
  flat.triangles = {{0, 1, 1}, {0, 0, 0}};
  CHECK_FALSE(MeshShape::build(flat, &problem));
  CHECK(problem.find("non-zero area") != std::string::npos);
  Mesh bad = points;
  bad.triangles = {{0, 1, 3}};
  CHECK_FALSE(MeshShape::build(bad, &problem));
  CHECK(problem.find("out of range") != std::string::npos);
}

TEST_CASE("a posed mesh collider sweeps like the analytic shape", "[mesh][colliders]") {
  // ColliderState::sweep sphere-traces the shape's distance: a thin mesh slab and the analytic
  // box of the same size stop a fast segment at the same fraction.
  ColliderState a, m;
  a.shape = analytic_box({0.01f, 2, 2});
  m.shape.kind = ShapeKind::Mesh;
  m.shape.mesh = build(test::box_mesh({0, 0, 0}, {0.01f, 2, 2}));
  for (ColliderState* c : {&a, &m}) {
    c->pose = Pose::from_trs({0.3f, 0.1f, 0}, {0, 30, 10}, 1.5f);
    c->prev_pose = c->pose;
  }
  const Vec3 from{-1, 0.2f, 0.1f}, to{1.5f, 0.1f, -0.2f};
  const float ta = a.sweep(from, to, 0.05f), tm = m.sweep(from, to, 0.05f);
  CHECK(ta < 1.0f);
  CHECK(tm == Approx(ta).margin(1e-5));
}
