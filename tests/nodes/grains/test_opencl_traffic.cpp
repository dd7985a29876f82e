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
  // it). These cross for each grain:
  //  up: the start positions (12 B) and velocities (12) on the first substep alone: from the
  //      second on the device makes them from what the last substep's end wrote there
  //      (GrainsSolver::carry_start), and a grain goes up only when its host floats differ from
  //      those (28 B: its index, position and velocity; none here, where nothing moves the
  //      grains between substeps). The device makes the predicted positions from them
  //      (GrainsSolver::predict), which the search of rows or planes and the solve take there.
  //      The radii, masses and inverse masses, equal for every grain here, are filled on the
  //      device from one word each (4 B): nothing a grain after the first substep;
  //  down: the written positions and velocities (24 B), which the device's velocity update and
  //      final collision test made. The neighbour rows stay there (after a search their number
  //      of entries comes back, 4 B in all), and so do the planes' rows and colliders, compared
  //      there with those the list was built from (their number of entries and the answer come
  //      back, 8 B in all);
  // and 136 B a collider up, 12 B for the force (gravity: one row for every grain). Beside these
  // a substep moves flags and per-block results (this scene is one block: a pass's largest
  // move, a round's flag, the built list's starts and links), under 1 KiB up and 4 KiB down, and
  // reads the partial results of its reductions, 1,024 runs each: the overlap statistics (3
  // doubles a run), the rows' box (7 floats), the rows' reach (1 float) and the Verlet test's
  // largest move (1 float, GrainsSolver::keep_rows), 61,440 B.
  test::Scene sc = test::layered_block(true);
  const double n = double(sc.size()), colliders = double(sc.colliders.size());
  const double runs = 1024 * (3 * 8 + 7 * 4 + 4 + 4);
  int built = 0, kept = 0;
  for (int k = 0; k < 120; ++k) {
    const opencl::Traffic before = sc.solver.device_traffic();
    const size_t lists = sc.solver.contact_lists_kept();
    sc.substep();
    const opencl::Traffic after = sc.solver.device_traffic();
    const bool list_kept = sc.solver.contact_lists_kept() > lists;
    (list_kept ? kept : built) += 1;
    const double entries = sc.solver.collider_planes().offsets->back();  // (brought after)
    const double sent = double(after.sent - before.sent),
                 received = double(after.received - before.received);
    INFO("substep " << k << (list_kept ? ", list kept" : ", list built") << ": sent " << sent / n
                    << " B a grain, received " << received / n << ", " << entries
                    << " plane entries");
    CHECK(sc.solver.finished_on_device());
    CHECK(sc.solver.collided_on_device());
    CHECK(sc.solver.finish_changed() == 0);
    CHECK(sc.solver.carried_start() == (k > 0));
    CHECK(sc.solver.carried_changed() == 0);
    CHECK(sc.solver.predicted_on_device());
    CHECK(sent <= (k > 0 ? 0 : 24) * n + 12 + 136 * colliders + 1024);
    CHECK(received <= 24 * n + runs + 4096);
  }
  // the premise: both kinds of substep were measured
  INFO(built << " substeps built a list, " << kept << " kept one");
  CHECK(built >= 10);
  CHECK(kept >= 10);
}

TEST_CASE("use_opencl: the Jacobi path's pre-stabilization sends no contact history",
          "[opencl][jacobi]") {
  // Two copies of the 512 falling grains with contact_solver jacobi (friction on: each substep
  // loads the contacts' carried slips, 12 B a row entry and a plane entry) run the same 48
  // substeps, the same bits; then one pre-stabilizes its next substep and the other does not.
  // Pre-stabilizing sends at most the start it moves (12 B a grain, and one float), the
  // pre-stabilized start the iterations then read (as much again), the planes (4 B a grain, 36
  // an entry) and 1 KiB of flags, but not the neighbour rows the device found; its passes
  // read no slip (gr_stabilize: no friction), so the slips go up once, with the iterations'
  // call, in both (else 12 B an entry more).
  test::Scene a = test::layered_block(true), b = test::layered_block(true);
  for (test::Scene* sc : {&a, &b}) sc->s.contact_solver = kContactJacobi;
  for (int k = 0; k < 48; ++k) a.substep(), b.substep();
  REQUIRE(a.P == b.P);
  REQUIRE(a.v == b.v);
  const double n = double(a.size());
  a.s.pre_stabilization = true;
  b.s.pre_stabilization = false;
  const opencl::Traffic a0 = a.solver.device_traffic(), b0 = b.solver.device_traffic();
  a.substep();
  b.substep();
  const double sent_a = double(a.solver.device_traffic().sent - a0.sent),
               sent_b = double(b.solver.device_traffic().sent - b0.sent);
  REQUIRE(a.solver.candidates());
  const double rows = double(a.solver.candidates()->indices.size());
  const double planes = double(a.solver.collider_planes().offsets->back());
  INFO(rows / n << " row entries and " << planes / n
                << " plane entries a grain; pre-stabilization sent " << (sent_a - sent_b) / n
                << " B a grain");
  CHECK(a.solver.stabilize_passes() > 0);
  // the rows' slips alone are more than the bound allows: sending them fails it
  const double most = 2 * (12 * n + 4) + 4 * (n + 1) + 36 * planes + 1024;
  CHECK(a.solver.rows_from_device());
  CHECK(12 * rows > most);
  CHECK(sent_a - sent_b <= most);
}

TEST_CASE("use_opencl: the Jacobi path keeps its rows and contact history on the device",
          "[opencl][jacobi]") {
  // contact_solver jacobi on the 512 falling grains (pre-stabilization and friction on), 120
  // substeps: each takes the rows the device's search found (that substep's, or the last one's,
  // kept), and the pre-stabilization's passes and the iterations read them there; the contacts'
  // slips are saved there at each substep's end and carried into the next there (looked up by
  // the grains' ids in the last rows, or found in place). A substep sends at most, a grain:
  // positions seven times, 12 B each and one float (the start the iterations read, the
  // pre-stabilized start, the positions pre-stabilization moves, the iterations' own, the plane
  // finder's, the search's, the history's save's); the ids of the grains now and in the last
  // substep for a lookup, 8 B; the planes' carried slips, 12 B an entry; and 136 B a collider,
  // 12 for the force and 1 KiB of flags. Sending the rows (4 B a grain and an entry) in any
  // call, or the rows' slips (12 B an entry), would fail that bound. A substep that kept its
  // rows (no lookup of the slips by id; from the 48th on) receives at most, a grain: positions
  // twice, 12 B each (after pre-stabilization and after the iterations); 4 B a plane entry (the
  // collider sums); the largest moves of the Verlet test and of each pre-stabilization pass
  // (1,024 floats each); and 1 KiB of flags. The friction each grain received (12 B) or the
  // pair sums (4 B an entry) coming back would fail that one.
  test::Scene sc = test::layered_block(true);
  sc.s.contact_solver = kContactJacobi;
  sc.s.pre_stabilization = true;
  const double n = double(sc.size()), colliders = double(sc.colliders.size());
  int stabilized = 0, kept = 0;
  for (int k = 0; k < 120; ++k) {
    const opencl::Traffic before = sc.solver.device_traffic();
    const size_t lookups = sc.solver.histories_looked_up_on_device();
    sc.substep();
    const double sent = double(sc.solver.device_traffic().sent - before.sent);
    const double received = double(sc.solver.device_traffic().received - before.received);
    const double rows = double(sc.solver.candidates()->indices.size());
    const double planes = double(sc.solver.collider_planes().offsets->back());
    const double most = 7 * (12 * n + 4) + 8 * n + 12 * planes + 136 * colliders + 12 + 1024;
    INFO("substep " << k << ": sent " << sent / n << " B a grain, " << rows / n
                    << " row entries and " << planes / n << " plane entries a grain");
    CHECK(sc.solver.rows_from_device());
    CHECK(sent <= most);
    CHECK(sent + 4 * (n + 1 + rows) > most);
    stabilized += sc.solver.stabilize_passes() > 0;
    // from the 48th substep on, the grains at rest, and only where the rows were kept
    if (k < 48 || sc.solver.histories_looked_up_on_device() > lookups) continue;
    ++kept;
    const double most_back =
        2 * 12 * n + 4 * planes + 4096 * (1 + sc.solver.stabilize_passes()) + 1024;
    INFO("received " << received / n << " B a grain");
    CHECK(received <= most_back);
    CHECK(received + 12 * n > most_back);
  }
  CHECK(kept >= 60);
  // the premises: pre-stabilization read the rows too, and the device saved every history
  CHECK(stabilized >= 100);
  CHECK(sc.solver.histories_saved_on_device() == 120);
}

TEST_CASE("use_opencl: the Jacobi path's pair sums stay on the device", "[opencl][jacobi]") {
  // The 512 falling grains with contact_solver jacobi, 120 substeps, twice from the same start:
  // the contacts' history made on the host (host_history), which reads each row entry's
  // accumulated normal correction (its pair sum, 4 B), so that they come back after the
  // iterations; and on the device, where they stay (they come back only for a rebuild of the
  // rows during the iterations or a history the device cannot make: GrainsSolver::sync_sums).
  // The two runs give the same positions every substep, and what the device's run receives is
  // the host's run's less exactly the pair sums.
  test::Scene there = test::layered_block(true);
  there.s.contact_solver = kContactJacobi;
  there.s.pre_stabilization = true;
  test::Scene host = there;
  host.s.host_history = true;
  const double n = double(there.size());
  for (int k = 0; k < 120; ++k) {
    const opencl::Traffic a0 = there.solver.device_traffic(), b0 = host.solver.device_traffic();
    there.substep();
    host.substep();
    REQUIRE(there.P == host.P);
    REQUIRE(there.v == host.v);
    const double less = double(host.solver.device_traffic().received - b0.received) -
                        double(there.solver.device_traffic().received - a0.received);
    const double rows = double(there.solver.candidates()->indices.size());
    INFO("substep " << k << ": " << rows / n << " row entries a grain, " << less / n
                    << " B a grain less received");
    CHECK(rows > 0);
    CHECK(less == 4 * rows);
  }
}
