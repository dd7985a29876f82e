// The rows and collider planes found again during the Jacobi iterations
// (update_neighbors_during_iterations, update_collisions_during_iterations) on the OpenCL
// device, within its one call of the substep's iterations (GrainsSolver::rebuilds_there,
// opencl::JacobiSolve::rebuild), against the same rebuilds made between device calls of an
// iteration each, the host carrying the sums over (host_rebuilds).
#include <catch2/catch.hpp>
#include <vector>

#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"

using namespace grains;

namespace {

// The contact-list tests' 512 falling grains (r = 4 cm) with contact_solver jacobi, thrown at
// 0.5 m/s into the corner of two walls 0.5 mm from the block's outer grains: the grains along a
// wall have its plane and the ground's in their rows, the corner's three, whose nearest-first
// order the iterations can change.
test::Scene cornered() {
  test::Scene sc = test::layered_block(true);
  sc.s.contact_solver = kContactJacobi;
  sc.s.pre_stabilization = true;
  sc.s.update_neighbors_during_iterations = true;
  sc.s.update_collisions_during_iterations = true;
  sc.add_collider(test::box({-0.068f, 0.5f, 0.3f}, {0.055f, 1.0f, 1.0f}));
  sc.add_collider(test::box({0.3f, 0.5f, -0.068f}, {1.0f, 1.0f, 0.055f}));
  for (size_t i = 0; i < sc.size(); ++i) sc.v[3 * i] = sc.v[3 * i + 2] = -0.35f;
  sc.impacts = true;
  return sc;
}

}  // namespace

TEST_CASE("use_opencl: the rows and planes found again during the iterations, there",
          "[opencl][jacobi]") {
  // The cornered block's 60 substeps (8 x 10 at 24 fps: the fall, the landing, the heap), its
  // rows and planes found again before every iteration but the first, twice: between device
  // calls of an iteration each, the positions going up and coming back at each and the host
  // carrying each pair's and each plane's sums, slips and impact slots over to the new rows
  // (host_rebuilds); and there, within the substep's one call (gr_k_carry_pairs,
  // gr_k_carry_planes, the same functions the host's carry calls: copies only), the substep
  // chained there from its prediction to its end (jacobi_on_device). The searches
  // are the host's, bit for bit (test_opencl_neighbours.cpp, test_opencl_planes.cpp), so the
  // two runs end every substep with the same positions, velocities and impact data, bit for
  // bit: with the friction pass once after the iterations and after each of them
  // (accurate_friction), and with Chebyshev's step.
  for (const int variant : {0, 1, 2}) {
    const bool accurate = variant == 1, chebyshev = variant == 2;
    INFO((accurate ? "accurate_friction" : chebyshev ? "chebyshev_rho 0.9" : "plain"));
    test::Scene host = cornered(), there;
    host.s.accurate_friction = accurate;
    if (chebyshev) host.s.chebyshev_rho = 0.9f;
    there = host;
    host.s.host_rebuilds = true;
    const double n = double(there.size());
    size_t planes = 0, corner = 0;
    for (int k = 0; k < 60; ++k) {
      INFO("substep " << k);
      const opencl::Traffic there0 = there.solver.device_traffic(),
                            host0 = host.solver.device_traffic();
      host.substep();
      there.substep();
      REQUIRE(host.P == there.P);
      REQUIRE(host.v == there.v);
      REQUIRE(host.impact_collider == there.impact_collider);
      REQUIRE(host.impact_impulse == there.impact_impulse);
      REQUIRE(host.impact_normal == there.impact_normal);
      REQUIRE(host.impact_point == there.impact_point);
      // and the last rebuild's planes (their ranges reach from the substep's start as it went
      // up, not from the pre-stabilized one)
      const GrainsSolver::PlaneRows a = host.solver.collider_planes(),
                                    b = there.solver.collider_planes();
      REQUIRE(*a.offsets == *b.offsets);
      REQUIRE(*a.collider == *b.collider);
      REQUIRE(*a.plane == *b.plane);
      // the substep chained there from its prediction to its end (jacobi_on_device), the
      // host's rebuilds keeping it here
      CHECK(there.solver.finished_on_device());
      CHECK(!host.solver.finished_on_device());
      // each of the host's 9 rebuilds sends the positions (12 B a grain) and brings them back,
      // at least; the chain sends no position after the first substep (the next test: nothing
      // a rebuild)
      const double there_sent = double(there.solver.device_traffic().sent - there0.sent);
      const double host_sent = double(host.solver.device_traffic().sent - host0.sent);
      INFO("sent " << there_sent / n << " B a grain, between calls " << host_sent / n);
      CHECK(host_sent >= there_sent + 9 * 12 * n);
      if (k > 0) CHECK(there_sent < 12 * n);
      for (size_t e = 0; e < there.impact_collider.size(); ++e) {
        planes += there.impact_collider[e] > 0;
        corner += there.impact_collider[e] > 0 && e % GrainsSolver::kContactSlots > 0;
      }
    }
    // the premises: the walls pushed, some grains against two colliders at once
    INFO(planes << " wall slots filled, " << corner << " past a grain's first");
    CHECK(planes > 100);
    CHECK(corner > 10);
  }
}

TEST_CASE("use_opencl: a rebuild during the iterations there reads back only its sizes",
          "[opencl][jacobi]") {
  // The cornered block after 30 substeps, one more substep with 10 iterations and with 20: the
  // ten more rebuilds there send nothing and bring back, each, only what sizes the new rows and
  // their sums (the search's box of the grains, gr_k_bounds' 1,024 parts of 7 floats; the
  // number of row entries; the longest row, gr_k_row_longest's 1,024 parts) and the planes'
  // number of entries, whatever the number of grains: no position crosses between iterations.
  test::Scene sc = cornered();
  sc.impacts = false;  // (their packed slots come back by the number filled)
  for (int k = 0; k < 30; ++k) sc.substep();
  opencl::Traffic step[2];
  for (const int iterations : {10, 20}) {
    test::Scene one = sc;
    one.s.constraint_iterations = iterations;
    const opencl::Traffic t0 = one.solver.device_traffic();
    one.substep();
    const opencl::Traffic t1 = one.solver.device_traffic();
    step[iterations / 10 - 1] = {t1.sent - t0.sent, t1.received - t0.received,
                                 t1.uploads - t0.uploads, t1.downloads - t0.downloads};
  }
  INFO("sent " << step[0].sent << " and " << step[1].sent << " B, received " << step[0].received
               << " and " << step[1].received << " B");
  CHECK(step[1].sent == step[0].sent);
  CHECK(step[1].received - step[0].received == 10 * (7 * 1024 * 4 + 4 + 1024 * 4 + 4));
}

TEST_CASE("use_opencl: the planes found again there reach from the substep's start",
          "[opencl][jacobi]") {
  // A plane's range reaches from a grain's start to where it is (gr_plane_range), which the
  // rebuilds take from the substep's start as it went up, as the host's do, not from the start
  // that pre-stabilization moved there. The 512 grains with a wall 2 cm into the block's first
  // column (pre-stabilization moves those grains 2 cm out of it) and a second wall 7 cm from
  // the first row's centres, beyond 1.5 radii (6 cm) but within that and the 2 cm moved: the
  // corner grains' rebuilt rows hold the second wall where the start is the one that went up.
  // Three substeps, chained there and with the host's rebuilds: the same planes, bit for bit.
  test::Scene host = test::layered_block(true);
  host.s.contact_solver = kContactJacobi;
  host.s.pre_stabilization = true;
  host.s.update_collisions_during_iterations = true;
  host.add_collider(test::box({-0.02f - 0.0275f, 0.5f, 0.3f}, {0.055f, 1.0f, 1.0f}));
  host.add_collider(test::box({0.3f, 0.5f, -0.07f - 0.0275f}, {1.0f, 1.0f, 0.055f}));
  test::Scene there = host;
  host.s.host_rebuilds = true;
  size_t far = 0;
  for (int k = 0; k < 3; ++k) {
    INFO("substep " << k);
    host.substep();
    there.substep();
    REQUIRE(host.P == there.P);
    CHECK(there.solver.finished_on_device());
    const GrainsSolver::PlaneRows a = host.solver.collider_planes(),
                                  b = there.solver.collider_planes();
    REQUIRE(*a.offsets == *b.offsets);
    REQUIRE(*a.collider == *b.collider);
    REQUIRE(*a.plane == *b.plane);
    for (int32_t c : *a.collider) far += c == 2;
  }
  INFO(far << " entries of the far wall");
  CHECK(far > 0);  // the premise
}
