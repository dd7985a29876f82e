// What crosses between the host and the device each substep on the OpenCL backend
// (opencl::Traffic, counted at every transfer; docs/opencl.md, "What still crosses each
// substep").
#include <catch2/catch.hpp>

#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"

using namespace grains;

TEST_CASE("use_opencl: what crosses between the host and the device each substep",
          "[opencl][gauss_seidel]") {
  // The default gauss_seidel, its contact list built and kept on the device (the contact-list
  // tests' 512 grains falling onto the ground, 120 substeps: some build a list, the rest keep
  // it). The host predicts and runs the final collision test, so these cross for each grain:
  //  up: the predicted positions (12 B), which the search of rows or planes takes and the solve
  //      copies there; the start positions (12), sent once a substep (Iterations::begin_substep)
  //      though three calls read them; the velocities (12), from which pre-stabilization's
  //      carried moves are taken back and the velocity update predicts: 36 B. The radii, masses
  //      and inverse masses, equal for every grain here, are filled on the device from one word
  //      each (4 B);
  //  down: the rows' offsets of the planes (4) and, after a search, of the neighbours (4); the
  //      written positions and velocities (24), which the device's velocity update made: 32 B
  //      at most;
  // and 4 B a plane entry down (its collider), 136 B a collider up, 12 B for the force (gravity:
  // one row for every grain), and 16 B for each grain the final collision test moved (its
  // index and position, for error control's overlap statistics, which read the rest where the
  // device wrote them). Beside these a substep moves flags and per-block results (this scene is
  // one block: a pass's largest move, a round's flag, the built list's starts and links), under
  // 1 KiB up and 4 KiB down, and reads the partial results of its reductions, 1,024 runs each:
  // the overlap statistics (3 doubles a run), the rows' box (7 floats) and the rows' reach (1
  // float), 57,344 B.
  test::Scene sc = test::layered_block(true);
  const double n = double(sc.size()), colliders = double(sc.colliders.size());
  const double runs = 1024 * (3 * 8 + 7 * 4 + 4);
  int built = 0, kept = 0;
  for (int k = 0; k < 120; ++k) {
    const opencl::Traffic before = sc.solver.device_traffic();
    const size_t lists = sc.solver.contact_lists_kept();
    sc.substep();
    const opencl::Traffic after = sc.solver.device_traffic();
    const bool list_kept = sc.solver.contact_lists_kept() > lists;
    (list_kept ? kept : built) += 1;
    const double entries = sc.solver.collider_planes().offsets->back();
    const double sent = double(after.sent - before.sent),
                 received = double(after.received - before.received);
    INFO("substep " << k << (list_kept ? ", list kept" : ", list built") << ": sent " << sent / n
                    << " B a grain, received " << received / n << ", " << entries
                    << " plane entries");
    const double moved = double(sc.solver.finish_changed());
    INFO(moved << " grains moved by the final collision test");
    CHECK(sc.solver.finished_on_device());
    CHECK(sent <= 36 * n + 12 + 16 * moved + 136 * colliders + 1024);
    CHECK(received <= 32 * n + 4 * entries + runs + 4096);
  }
  // the premise: both kinds of substep were measured
  INFO(built << " substeps built a list, " << kept << " kept one");
  CHECK(built >= 10);
  CHECK(kept >= 10);
}
