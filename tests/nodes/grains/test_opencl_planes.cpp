// The collider planes found on an OpenCL device (opencl::Iterations::find_planes,
// kernels/planes.h) against the CPU path's (GrainsSolver::find_planes), on PoCL's CPU device:
// the shapes' distances, poses and velocities are one definition (engine/collider_shape.h) that
// neither side compiles with fused multiply-adds, so a substep's rows must be the same, bit for
// bit: every analytic shape, rotated, scaled and moving, grains inside and outside them,
// fixed grains, and a search whose positions and radii are not the device's search's.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <random>
#include <set>
#include <vector>

#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/cloud.h"
#include "tests/support/support.h"

using namespace grains;
using test::unit;

namespace {

ColliderState shape(ShapeKind kind, const char* name) {
  ColliderState c;
  c.name = name;
  c.shape.kind = kind;
  return c;
}

// 4,000 grains of radii 0.01-0.04 m scattered over 2 m x 1.2 m x 2 m at up to 3 m/s, every
// 50th fixed (mass 0), among an incline, a box, a sphere, a torus and a capsule, the last four
// turned, scaled and moving: each pose a function of time
test::Scene crowd() {
  test::Scene sc;
  std::mt19937 rng(7);
  for (int i = 0; i < 4000; ++i) {
    const Vec3 p{2.0f * unit(rng) - 1.0f, 1.2f * unit(rng) - 0.2f, 2.0f * unit(rng) - 1.0f};
    const Vec3 v{6.0f * unit(rng) - 3.0f, 6.0f * unit(rng) - 3.0f, 6.0f * unit(rng) - 3.0f};
    sc.add(p, 0.01f + 0.03f * unit(rng), i % 50 == 0 ? 0.0f : 1.0f, v);
  }
  sc.add_collider(test::incline(12.0f));
  ColliderState b = shape(ShapeKind::Box, "box");
  b.shape.size = {0.6f, 0.3f, 0.4f};
  sc.add_collider(b, [](float t) {
    return Pose::from_trs({-0.4f + t, 0.3f, 0.2f}, {10, 20 + 90 * t, 30}, 1.3f);
  });
  ColliderState s = shape(ShapeKind::Sphere, "sphere");
  s.shape.radius = 0.25f;
  sc.add_collider(s, [](float t) {
    return Pose::from_trs({0.5f, 0.4f - 2 * t, -0.3f}, {0, 0, 0}, 0.9f);
  });
  ColliderState o = shape(ShapeKind::Torus, "torus");
  o.shape.radius = 0.3f, o.shape.tube = 0.08f;
  sc.add_collider(o, [](float t) {
    return Pose::from_trs({0.2f, 0.6f, 0.5f}, {40 + 200 * t, 0, 15}, 1.1f);
  });
  ColliderState k = shape(ShapeKind::Capsule, "capsule");
  k.shape.radius = 0.1f, k.shape.height = 0.5f;
  sc.add_collider(k, [](float t) {
    return Pose::from_trs({-0.5f, 0.5f, -0.5f}, {0, 30, 60 - 100 * t}, 0.8f);
  });
  sc.s = test::settings(24, 4, 10);
  return sc;
}

// one substep of `sc` on each backend: the same planes
void same_planes(const test::Scene& sc) {
  test::Scene cpu = sc, dev = sc;
  dev.s.use_opencl = true;
  cpu.substep();
  dev.substep();
  REQUIRE(dev.solver.planes_found_on_device() > 0);
  REQUIRE(cpu.solver.planes_found_on_device() == 0);
  const GrainsSolver::PlaneRows a = cpu.solver.collider_planes(), b = dev.solver.collider_planes();
  // the premise: rows of every collider, grains with more than one, entries that move
  std::set<int32_t> which(a.collider->begin(), a.collider->end());
  CHECK(which.size() == sc.colliders.size());
  size_t several = 0;
  for (size_t i = 0; i < sc.size(); ++i) several += (*a.offsets)[i + 1] - (*a.offsets)[i] > 1;
  CHECK(several > 10);
  INFO("entries " << a.collider->size() << ", grains with several " << several);
  CHECK(a.collider->size() > 500);
  REQUIRE(*b.offsets == *a.offsets);
  REQUIRE(*b.collider == *a.collider);
  REQUIRE(b.plane->size() == a.plane->size());
  size_t differ = 0;
  for (size_t e = 0; e < a.plane->size(); ++e)
    differ += std::memcmp(&(*a.plane)[e], &(*b.plane)[e], sizeof(float)) != 0;
  REQUIRE(differ == 0);
}

}  // namespace

TEST_CASE("use_opencl: the device's collider planes are the CPU's, bit for bit", "[opencl]") {
  test::Scene sc = crowd();
  SECTION("after the device's search: its positions and radii") {
    same_planes(sc);
  }
  SECTION("without a search (no internal collisions): the planes take their own") {
    sc.s.internal_collisions_weight = 0;
    same_planes(sc);
  }
  SECTION("rebuilt during the iterations, from the iterations' positions") {
    sc.s.update_collisions_during_iterations = true;
    same_planes(sc);
  }
}
