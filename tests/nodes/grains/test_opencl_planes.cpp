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

#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/cloud.h"
#include "tests/support/meshes.h"
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

// crowd()'s grains among triangle meshes: a closed sphere (320 triangles) and a closed box
// (its faces split, welded again by MeshShape), both turned, scaled and moving, an open sheet
// (a shell, tilted) and a mesh the sphere's collider shares with a second one, beside the
// analytic incline: grains inside the solids, on both sides of the sheet
test::Scene crowd_meshes() {
  test::Scene sc = crowd();
  std::string problem;
  ColliderState ball = shape(ShapeKind::Mesh, "ball");
  ball.shape.mesh = MeshShape::build(test::sphere_mesh({0, 0, 0}, 0.25f, 2), &problem);
  ColliderState box = shape(ShapeKind::Mesh, "box mesh");
  box.shape.mesh = MeshShape::build(test::box_mesh({0, 0, 0}, {0.6f, 0.3f, 0.4f}, true), &problem);
  ColliderState sheet = shape(ShapeKind::Mesh, "sheet");
  sheet.shape.mesh = MeshShape::build(test::quad_mesh(0.5f), &problem);
  REQUIRE(ball.shape.mesh);
  REQUIRE(box.shape.mesh);
  REQUIRE(sheet.shape.mesh);
  REQUIRE(ball.shape.mesh->closed());
  REQUIRE(box.shape.mesh->closed());
  REQUIRE(!sheet.shape.mesh->closed());
  test::Scene out = sc;
  out.colliders.clear();
  out.collider_motion.clear();
  out.add_collider(sc.colliders[0]);  // the incline
  out.add_collider(box, [](float t) {
    return Pose::from_trs({-0.4f + t, 0.3f, 0.2f}, {10, 20 + 90 * t, 30}, 1.3f);
  });
  out.add_collider(ball, [](float t) {
    return Pose::from_trs({0.5f, 0.4f - 2 * t, -0.3f}, {0, 0, 0}, 0.9f);
  });
  out.add_collider(sheet, [](float t) {
    return Pose::from_trs({0.2f, 0.5f, 0.3f}, {25, 40 * t, 10}, 1.1f);
  });
  out.add_collider(ball, [](float t) {
    return Pose::from_trs({-0.5f, 0.5f + t, -0.5f}, {0, 30, 60}, 0.8f);
  });
  return out;
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

TEST_CASE("use_opencl: a mesh collider's planes found on the device are the CPU's, bit for bit",
          "[opencl][mesh]") {
  // The meshes' queries (engine/mesh_query.h) run there on the arrays MeshShape built, in
  // double precision without fused multiply-adds, as MeshShape's own queries run on the host:
  // the same rows, normals, surface points and velocities, bit for bit, solid and shell alike,
  // one mesh shared by two colliders.
  test::Scene sc = crowd_meshes();
  same_planes(sc);
  // the same substep with the meshes' queries on the host (host_mesh): the host's planes
  test::Scene here = sc;
  here.s.use_opencl = true;
  here.s.host_mesh = true;
  here.substep();
  CHECK(here.solver.planes_found_on_device() == 0);
}

TEST_CASE("use_opencl: the device compares the planes' rows and colliders with those it kept",
          "[opencl]") {
  // Three grains of radius 0.05 m beside a box 1 m high standing on the ground: one resting on
  // the ground, one high above it (no plane), one resting on the box (its plane the box's). The
  // device's planes of these (rows and colliders left there) are kept (keep_planes), then found
  // again for positions that give the same number of entries: the same positions (the same
  // rows), the first two grains swapped in height (the same count, other rows), the third on
  // the ground (the same rows, another collider); and for one grain fewer. Only the first
  // compares the same, and what comes back with the rows (fetch_planes) is what a search that
  // brings them gives.
  const std::vector<ColliderState> world = {test::ground(),
                                            test::box({2.0f, 0.5f, 0.0f}, {1.0f, 1.0f, 1.0f})};
  std::vector<gr_collider> colliders;
  for (const ColliderState& c : world) colliders.push_back(to_gr(c));
  const float r = 0.05f, origin[3] = {0, 0, 0}, scale = 2.0f;
  const std::vector<float> radius(3, r), inv_mass(3, 1.0f);
  const std::vector<float> resting = {0.0f, r, 0.0f, 0.5f, 3.0f, 0.0f, 2.0f, 1.0f + r, 0.0f},
                           swapped = {0.0f, 3.0f, 0.0f, 0.5f, r, 0.0f, 2.0f, 1.0f + r, 0.0f},
                           grounded = {0.0f, r, 0.0f, 0.5f, 3.0f, 0.0f, 3.5f, r, 0.0f};
  opencl::Iterations device;
  std::vector<uint32_t> offsets, brought;
  std::vector<float> plane;
  std::vector<int32_t> which, brought_which;
  auto found = [&](const std::vector<float>& P, size_t n, bool rows_stay) {
    bool same = true;
    device.find_planes(colliders.data(), colliders.size(), origin, scale, P.data(), P.data(),
                       radius.data(), inv_mass.data(), n, false, false, true, rows_stay, &offsets,
                       &plane, &which, &same);
    return same;
  };
  for (const auto* P : {&resting, &swapped, &grounded}) {
    found(*P, 3, false);
    const std::vector<uint32_t> rows = offsets;
    const std::vector<int32_t> of = which;
    REQUIRE(rows.back() == 2);  // the premise: two entries each
    found(*P, 3, true);
    CHECK(offsets.back() == 2);
    device.fetch_planes(nullptr, &brought, &brought_which);
    CHECK(brought == rows);
    CHECK(brought_which == of);
  }
  found(resting, 3, true);
  device.keep_planes();
  CHECK(found(resting, 3, true));
  CHECK(!found(swapped, 3, true));
  CHECK(!found(grounded, 3, true));
  CHECK(!found(resting, 2, true));
  CHECK(found(resting, 3, true));  // what was kept stays kept
}

TEST_CASE("use_opencl: the planes' rows compared on the device with the contact list's",
          "[opencl][gauss_seidel]") {
  // The contact-list tests' 512 grains, lifted 0.2 m and staggered by up to 2 cm so that they
  // come within the ground's reach a few at a time, falling onto it for 90 substeps, twice: the
  // planes' rows and colliders brought back every substep and compared here with those the
  // contact list was built from (fetch_plane_rows), and left on the device, which keeps the
  // list's and compares them there. The comparison decides whether the list is kept: the same
  // decisions give the same lists, so the two runs keep the same number of them and end with
  // the same positions and velocities, bit for bit. The second receives, each substep, 4 bytes
  // a grain and 4 an entry less (the rows' offsets but the last, the entries' colliders), less
  // the comparison's answer (4 bytes) where it ran.
  test::Scene fetched = test::layered_block(true);
  for (size_t i = 0; i < fetched.size(); ++i)
    fetched.P[3 * i + 1] += 0.2f + 0.002f * float((7 * i) % 11);
  test::Scene compared = fetched;
  fetched.s.fetch_plane_rows = true;
  const double n = double(fetched.size());
  size_t entries_seen = 0, changed = 0, last_entries = 0;
  for (int k = 0; k < 90; ++k) {
    const opencl::Traffic f0 = fetched.solver.device_traffic(),
                          c0 = compared.solver.device_traffic();
    fetched.substep();
    compared.substep();
    const double saved = double(fetched.solver.device_traffic().received - f0.received) -
                         double(compared.solver.device_traffic().received - c0.received);
    const size_t entries = fetched.solver.collider_planes().offsets->back();
    INFO("substep " << k << ": " << entries << " plane entries, " << saved << " B less");
    CHECK((saved == 4 * n + 4 * double(entries) ||
           (entries > 0 && saved == 4 * n + 4 * double(entries) - 4)));
    CHECK(fetched.solver.contact_lists_kept() == compared.solver.contact_lists_kept());
    entries_seen += entries > 0;
    changed += k > 0 && entries != last_entries;
    last_entries = entries;
  }
  // the premise: the planes changed over the run (grains reached the ground), and lists were
  // both kept and built
  CHECK(entries_seen > 40);
  CHECK(changed >= 2);
  CHECK(compared.solver.contact_lists_kept() > 10);
  CHECK(compared.solver.contact_lists_kept() < 80);
  CHECK(fetched.P == compared.P);
  CHECK(fetched.v == compared.v);
}
