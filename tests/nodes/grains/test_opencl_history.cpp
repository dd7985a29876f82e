// The Jacobi path's contact history kept on the OpenCL device
// (kernels/history.h, opencl/history.cpp; docs/opencl.md, "What still crosses each substep").
#include <catch2/catch.hpp>
#include <numeric>

#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"

using namespace grains;

TEST_CASE("use_opencl: the Jacobi path's contact history made on the device is the host's",
          "[opencl][jacobi]") {
  // The 512 falling grains with ids, contact_solver jacobi (friction and pre-stabilization on),
  // 120 substeps, twice: the contacts' slips saved and carried on the host (host_history), and
  // on the device where its search's rows are (the ground's saved and carried there too, found
  // by id in its last planes, or as the grain's own where the order is the same). The rows are
  // rebuilt through the fall (each contact's slip looked up by the grains' ids in the last
  // substep's rows) and kept once the grains lie on the ground (each slip where it was saved); at
  // the 40th substep the grains come in another order, at the 80th 13 are killed and 13 born in
  // the air, and at the 60th the device's run saves its state and reads it back (the saved slips
  // come back for it).
  // Both write the same floats (kernels/history.h: no multiply and add fused on either side): the
  // two runs end every substep with the same positions and velocities, bit for bit.
  // With update_neighbors_during_iterations the rows are found again during the iterations,
  // there (rebuilds_there: the device carries its pair sums and slips over to the new rows,
  // gr_carry_pair_row), against the host's carrying its own.
  for (bool rebuild : {false, true}) {
    INFO("update_neighbors_during_iterations " << rebuild);
    test::Scene host = test::layered_block(true);
    host.ids.resize(host.size());
    std::iota(host.ids.begin(), host.ids.end(), 0);
    host.s.contact_solver = kContactJacobi;
    host.s.pre_stabilization = true;
    host.s.update_neighbors_during_iterations = rebuild;
    test::Scene there = host;
    host.s.host_history = true;
    size_t reordered = 0, born_total = 0;
    for (int k = 0; k < 120; ++k) {
      INFO("substep " << k);
      const size_t n = there.size();
      std::vector<size_t> order;
      size_t born = 0;
      if (k == 40) {
        order = test::blocks_reversed(n);
      } else if (k == 80) {
        order = test::killed_and_born(n, &born);
      }
      if (!order.empty())
        for (test::Scene* sc : {&host, &there}) test::reorder(*sc, order, {0.1f, 1.2f, 0.1f});
      if (!order.empty()) ++reordered, born_total += born;
      if (k == 60) {
        StateWriter w;
        there.solver.save_state(w);
        StateReader r(w.bytes(), "round trip");
        there.solver.load_state(r);
      }
      host.substep();
      there.substep();
      REQUIRE(host.P == there.P);
      REQUIRE(host.v == there.v);
    }
    CHECK(reordered == 2);
    CHECK(born_total == 13);
    // the premises: the host made every history of its run; the device all of its own but the 20
    // substeps after the state was read back, whose kept rows are the state's until the new order
    // at the 80th has them searched again, looking slips up by id (the fall, the new orders) and
    // finding them in place (at rest)
    const size_t saved = there.solver.histories_saved_on_device();
    const size_t looked_up = there.solver.histories_looked_up_on_device();
    INFO(saved << " histories saved on the device, " << looked_up << " looked up there");
    CHECK(host.solver.histories_saved_on_device() == 0);
    CHECK(host.solver.histories_looked_up_on_device() == 0);
    // the ground's slips (gr_save_plane_slips) saved there where the iterations' end stays there:
    // every substep's, one call of the iterations, the rows rebuilt during them there too
    const size_t planes = there.solver.plane_histories_saved_on_device();
    CHECK(host.solver.plane_histories_saved_on_device() == 0);
    CHECK(planes == 120);
    // and kept there with the planes, which stay there (jacobi_planes_stay), the next substep's
    // carried slips made there from them: every substep's but the first (no history) and the
    // one after the state was read back (the state's history, looked up here)
    CHECK(host.solver.plane_histories_loaded_on_device() == 0);
    CHECK(there.solver.plane_histories_loaded_on_device() == 118);
    if (rebuild) {  // every substep's rows found again: every history saved, then looked up
      CHECK(saved >= 110);
      CHECK(looked_up >= 100);
    } else {
      CHECK(saved >= 100);
      CHECK(looked_up >= 20);
      CHECK(saved - looked_up >= 40);
    }
  }
}
