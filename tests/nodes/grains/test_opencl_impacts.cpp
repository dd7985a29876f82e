// Impact data made on the OpenCL device at the end of the substep (kernels/impact.h:
// gr_k_impact_loads, gr_k_final_collision, gr_k_impact_pack), against the host's from the same
// state.
#include <catch2/catch.hpp>
#include <cfloat>
#include <vector>

#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"

using namespace grains;

namespace {

// One substep of `start` with impact data made on the host (host_finish: the host ends the
// substep) and where the device can (no host_finish), and once on the device without impact
// data. The passes are the same on both sides, so are the positions (test_opencl_finish.cpp,
// test_opencl.cpp for jacobi's chain), and
// so are each slot's collider, normal and point: the same floats through the same unfused
// operations (kernels/impact.h). A momentum adds to the moves the velocity the final collision
// test took away, v - v_loop, where the test acted; each side's velocities may differ within the
// rounding of the velocity update (8 eps (|v| + |v_start| + dt g), test_opencl_finish.cpp) and of
// the test's friction, so the momenta agree within m x 16 eps (|v| + |v_start| + dt g). `there`:
// whether the device makes them (its colliders' queries there). Returns the slots filled.
// gauss_seidel's contacts' loads, or jacobi's sums of the planes' moves, (zeros to start: one
// 4-byte word, sent for the latter) stay there.
size_t compare(const test::Scene& start, bool there) {
  test::Scene host = start, device = start, plain = start;
  host.impacts = device.impacts = true;
  host.s.host_finish = true;
  const opencl::Traffic d0 = device.solver.device_traffic(), p0 = plain.solver.device_traffic();
  host.substep();
  device.substep();
  plain.substep();
  CHECK(!host.solver.finished_on_device());
  CHECK(device.solver.finished_on_device() == there);
  CHECK(host.P == device.P);
  const size_t K = GrainsSolver::kContactSlots, slots = K * start.size();
  size_t filled = 0, worse = 0;
  for (size_t e = 0; e < slots; ++e) {
    const size_t i = e / K;
    const float bound = 16 * FLT_EPSILON * start.mass[i] *
                        (length(host.vel(i)) + length(start.vel(i)) + start.s.dt * test::kG);
    filled += host.impact_collider[e] >= 0;
    worse += length(load3(host.impact_impulse.data(), e) - load3(device.impact_impulse.data(), e)) >
             bound;
  }
  CHECK(host.impact_collider == device.impact_collider);
  CHECK(host.impact_normal == device.impact_normal);
  CHECK(host.impact_point == device.impact_point);
  CHECK(worse == 0);
  // what the device's impact data cost: the filled slots come back packed, 44 bytes each (the
  // slot, the collider, the momentum, normal and point), beside their count, 4 bytes each way;
  // everything else crosses as without impact data
  if (there) {
    const opencl::Traffic d1 = device.solver.device_traffic(), p1 = plain.solver.device_traffic();
    CHECK((d1.received - d0.received) - (p1.received - p0.received) == 4 + 44 * filled);
    const bool sums = start.s.contact_solver != kContactGaussSeidel;
    CHECK((d1.sent - d0.sent) - (p1.sent - p0.sent) == (sums ? 8u : 4u));
  }
  return filled;
}

}  // namespace

TEST_CASE("use_opencl: the device makes the impact data as the host does",
          "[opencl][gauss_seidel][impacts]") {
  // The contact-list tests' 512 grains falling onto the ground, compared after 30 substeps (the
  // lower layers landing) and 90 (at rest): the bottom layer's 64 grains touch the ground.
  test::Scene sc = test::layered_block(true);
  int done = 0;
  for (const int settle : {30, 90}) {
    for (; done < settle; ++done) sc.substep();
    INFO("after " << settle << " substeps");
    CHECK(compare(sc, true) == 64);
  }
  {  // jacobi's chain on the device, landing
    test::Scene jacobi = test::layered_block(true);
    jacobi.s.contact_solver = kContactJacobi;
    for (int k = 0; k < 30; ++k) jacobi.substep();
    INFO("jacobi");
    CHECK(compare(jacobi, true) == 64);
  }
  // test::shot_plate's 16 grains shot at 30 m/s through a plate thinner than their radius:
  // the final collision test puts each back on top and takes its speed into the plate away,
  // which is all of its impact (each one slot). An analytic box, and the same plate as a mesh
  // (engine/mesh_query.h there): the device's test and impact data; the mesh plate with its
  // queries on the host (host_mesh, as a device without double precision has them): the
  // host's.
  for (const int variant : {0, 1, 2}) {
    const bool mesh = variant > 0, mesh_here = variant == 2;
    INFO((mesh ? (mesh_here ? "a mesh plate, its queries on the host" : "a mesh plate")
               : "a box plate"));
    test::Scene pl = test::shot_plate(mesh);
    pl.s.host_mesh = mesh_here;
    REQUIRE((!mesh || pl.colliders[0].shape.mesh));
    CHECK(compare(pl, !mesh_here) == 16);
  }
}
