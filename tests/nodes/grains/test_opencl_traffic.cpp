// What crosses between the host and the device each substep on the OpenCL backend
// (opencl::Traffic, counted at every transfer; docs/opencl.md, "What still crosses each
// substep").
#include <catch2/catch.hpp>

#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/meshes.h"

using namespace grains;

namespace {

// One substep of each of two copies of a scene, which give the same positions and velocities
// bit for bit: what the second sent and received more than the first
struct More {
  double sent, received;
};
More twin_substep(test::Scene& a, test::Scene& b) {
  const opencl::Traffic a0 = a.solver.device_traffic(), b0 = b.solver.device_traffic();
  a.substep();
  b.substep();
  REQUIRE(a.P == b.P);
  REQUIRE(a.v == b.v);
  const opencl::Traffic a1 = a.solver.device_traffic(), b1 = b.solver.device_traffic();
  return {double(b1.sent - b0.sent) - double(a1.sent - a0.sent),
          double(b1.received - b0.received) - double(a1.received - a0.received)};
}

// the 512 falling grains (test::layered_block) with contact_solver jacobi and
// pre-stabilization
test::Scene jacobi_block() {
  test::Scene sc = test::layered_block(true);
  sc.s.contact_solver = kContactJacobi;
  sc.s.pre_stabilization = true;
  return sc;
}

}  // namespace

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
  // The same with the ground as a triangle mesh (a closed slab whose top is the plane), whose
  // queries the device makes (engine/mesh_query.h): its arrays go up once, on the first substep
  // (Iterations::set_meshes: a 52-byte record, its nodes, triangles, vertices and normals), and
  // nothing else crosses for it.
  for (const bool mesh : {false, true}) {
    INFO((mesh ? "the ground as a mesh" : "the ground plane"));
    test::Scene sc = test::layered_block(true);
    double mesh_bytes = 0;
    if (mesh) {
      std::string problem;
      ColliderState& ground = sc.colliders[0];
      ground.shape.kind = ShapeKind::Mesh;
      ground.shape.mesh =
          MeshShape::build(test::box_mesh({0.3f, -0.5f, 0.3f}, {4, 1, 4}), &problem);
      REQUIRE(ground.shape.mesh);
      REQUIRE(ground.shape.mesh->closed());
      const MeshShape& m = *ground.shape.mesh;
      const double t = double(m.triangle_count()), v = double(m.mesh().vertices.size());
      mesh_bytes = 52 + 32 * double(m.node_count()) + 4 * (3 * t + 3 * v + 3 * t + 9 * t + 3 * v);
    }
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
      CHECK(sent <= (k > 0 ? 0 : 24 * n + mesh_bytes) + 12 + 136 * colliders + 1024);
      CHECK(received <= 24 * n + runs + 4096);
    }
    // the premise: both kinds of substep were measured
    INFO(built << " substeps built a list, " << kept << " kept one");
    CHECK(built >= 10);
    CHECK(kept >= 10);
  }
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
  // the grains' ids in the last rows, or found in place). The substep runs there from its
  // prediction to its end (GrainsSolver::jacobi_on_device), which makes the next one's start
  // there (carry_start), and the collider planes' carried slips are made there from those it
  // saved with its planes (the grains the same, in the same order: no ids go up for a lookup):
  // after the first, a substep sends at most 136 B a collider, 12 for the force and 1 KiB of
  // flags and sums (their zeros filled from one word). Sending the rows (4 B a grain and an
  // entry) in any call, the rows' slips (12 B an entry), the grains' ids (4 B a grain) or a
  // grain's position (12 B) would fail that bound.
  // A substep that kept its rows (no lookup of the slips by id; from the 48th on) receives at
  // most, a grain: the written positions and velocities (24 B); the number of plane entries
  // (4 B in all: the planes, their colliders and sums and their saved slips stay there); the
  // largest moves of the Verlet test and of each pre-stabilization pass (1,024 floats each);
  // the overlap statistics where they were measured along the rows on the device (1,024 runs
  // of 3 doubles), or the rows where they came back for them (4 B a grain and an entry,
  // GrainsSolver::read_rows); and 1 KiB of flags. The friction each grain received (12 B), the
  // pair sums (4 B an entry), the planes' rows (4 B a grain) or the iterations' positions
  // (12 B) coming back would fail that one.
  test::Scene sc = jacobi_block();
  const double n = double(sc.size()), colliders = double(sc.colliders.size());
  int stabilized = 0, kept = 0;
  for (int k = 0; k < 120; ++k) {
    const opencl::Traffic before = sc.solver.device_traffic();
    const size_t lookups = sc.solver.histories_looked_up_on_device();
    const size_t overlaps = sc.solver.overlaps_on_device(), back = sc.solver.rows_brought_back();
    sc.substep();
    const double sent = double(sc.solver.device_traffic().sent - before.sent);
    const double received = double(sc.solver.device_traffic().received - before.received);
    const double rows = double(sc.solver.candidate_entries());
    const double planes = double(sc.solver.plane_entries());
    // the first substep's start, 12 B a grain (its velocities, zero, filled from one word)
    const double most = (k == 0 ? 12 * n + 4 : 0) + 136 * colliders + 12 + 1024;
    INFO("substep " << k << ": sent " << sent / n << " B a grain, " << rows / n
                    << " row entries and " << planes / n << " plane entries a grain");
    CHECK(sc.solver.rows_from_device());
    CHECK(sc.solver.finished_on_device());
    CHECK(sent <= most);
    if (k == 0) CHECK(sent + 4 * n > most);  // the start did go up
    stabilized += sc.solver.stabilize_passes() > 0;
    // from the 48th substep on, the grains at rest, and only where the rows were kept
    if (k < 48 || sc.solver.histories_looked_up_on_device() > lookups) continue;
    ++kept;
    const bool measured_there = sc.solver.overlaps_on_device() > overlaps;
    const bool came_back = sc.solver.rows_brought_back() > back;
    const double most_back = 24 * n + 4 + 4096 * (1 + sc.solver.stabilize_passes()) +
                             (measured_there ? 24576 : 0) + (came_back ? 4 * (n + 1 + rows) : 0) +
                             1024;
    INFO("received " << received / n << " B a grain, " << planes / n << " plane entries a grain");
    CHECK(received <= most_back);
    CHECK(received + 4 * n > most_back);
  }
  CHECK(kept >= 60);
  // the premises: pre-stabilization read the rows too, and the device saved every history
  CHECK(stabilized >= 100);
  CHECK(sc.solver.histories_saved_on_device() == 120);
  CHECK(sc.solver.plane_histories_saved_on_device() == 120);
  CHECK(sc.solver.plane_histories_loaded_on_device() == 119);
}

TEST_CASE("use_opencl: the Jacobi path's rows stay on the device", "[opencl][jacobi]") {
  // contact_solver jacobi on the 512 falling grains (pre-stabilization and friction on), 120
  // substeps, twice from the same start: the rows the device's search found stay there (their
  // number of entries comes back), read there by the passes, the contact history, the Verlet
  // skin and test, error control's overlap statistics and the longest row's measure; and they
  // come back after each search (fetch_rows), read on the host by those that read them there.
  // The same positions and velocities every substep, bit for bit.
  //
  // What stays costs what the reads along the rows send (GrainsSolver::read_rows): the overlap
  // statistics, measured each substep here, read the end positions the host wrote, 12 B a
  // grain. A search's rows stay unless the reads since the last search sent, or would have
  // sent, more than that search's rows take to bring (4 B a grain and an entry); rows that
  // stayed come back at the read that would pass that. Until substep 40 each search's substep
  // receives, where its rows stayed, the rows less, but for what the device's reductions bring
  // instead, 1,024 runs each: the longest row (4 B a run), the rows' reach (4: the Verlet skin
  // of rows cut at max_neighbors, 32) and the overlap statistics (24).
  //
  // Substeps 40 to 79 rebuild the rows during the iterations (carried over on the host, which
  // brings the first search's), 60 to 89 write the solver's state and read it back after each
  // substep (the host then looks up the contacts' slips in rows found on the device), and 100
  // to 109 make the contacts' history on the host (host_history: the first, after searches at
  // 98 and 99 whose rows stayed, looks the slips up in the rows the device saved them with,
  // which come back with them; query scales changed at 98 and 99 alone make the three search).
  // The longest row measured there is the rows' own.
  // (host_finish: the end made here, whose written positions the statistics send; where the
  // device ends the substep they read its own, and the rows stay until the next search)
  test::Scene there = jacobi_block();
  there.s.host_finish = true;
  test::Scene fetched = there;
  fetched.s.fetch_rows = true;
  const double n = double(there.size());
  const float scale = there.s.neighbor_query_scale;
  int stayed = 0, fetched_first = 0, brought = 0;
  double reads = 0, rows_bytes = 0;  // since the last search, and what its rows take
  bool stale = false;                // the rows are on the device alone
  for (int k = 0; k < 120; ++k) {
    for (test::Scene* sc : {&there, &fetched}) {
      sc->s.update_neighbors_during_iterations = k >= 40 && k < 80;
      sc->s.host_history = k >= 100 && k < 110;
      sc->s.neighbor_query_scale = (k == 98 ? 1.5f : k == 99 ? 1.25f : 1.0f) * scale;
    }
    const size_t left = there.solver.rows_left_on_device(), searches = there.solver.rows_searched(),
                 back = there.solver.rows_brought_back();
    const double less = twin_substep(there, fetched).received;
    const double rows = double(there.solver.candidate_entries());
    const bool search = there.solver.rows_searched() > searches;
    const bool stay = there.solver.rows_left_on_device() > left;
    const bool came_back = there.solver.rows_brought_back() > back;
    INFO("substep " << k << ": " << rows / n << " row entries a grain, " << less / n
                    << " B a grain less received" << (search ? ", searched" : "")
                    << (stay ? ", the rows stayed" : "") << (came_back ? ", came back" : ""));
    // the Verlet rows are not kept: after the first, each search's reads are one substep's
    if (k > 40 && k < 80) CHECK(stay);
    if (k == 99) CHECK(stay);
    if (k < 40) {
      if (search) {
        CHECK(stay == !(k > 0 && reads > rows_bytes));
        stayed += stay, fetched_first += !stay;
        if (stay) CHECK(less == 4 * (n + 1 + rows) - 4 - 1024 * (4 + 4 + 24));
        reads = 0, rows_bytes = 4 * (n + 1 + rows), stale = stay;
      }
      // this substep's read, made where the rows are: they come back where it passes them
      const bool passes = stale && reads + 12 * n > rows_bytes;
      CHECK(came_back == passes);
      brought += passes;
      stale = stale && !passes;
      reads += 12 * n;
    }
    if (k >= 60 && k < 90)
      for (test::Scene* sc : {&there, &fetched}) {
        StateWriter w;
        sc->solver.save_state(w);
        StateReader r(w.bytes(), "round trip");
        sc->solver.load_state(r);
      }
  }
  // the premises: every case was met
  INFO(stayed << " searches' rows stayed, " << fetched_first << " came back at once, " << brought
              << " later");
  CHECK(stayed >= 5);
  CHECK(fetched_first >= 1);
  CHECK(brought >= 1);
  CHECK(fetched.solver.rows_left_on_device() == 0);
  const size_t longest = there.solver.longest_row();
  const NeighborList* rows = there.solver.candidates();  // brings them
  REQUIRE(rows);
  size_t most = 0;
  for (size_t i = 0; i < there.size(); ++i) most = std::max<size_t>(most, rows->count(i));
  CHECK(longest == most);
  CHECK(longest == fetched.solver.longest_row());
}

TEST_CASE("use_opencl: the Jacobi path's history save takes the iterations' end on the device",
          "[opencl][jacobi]") {
  // The 512 falling grains with contact_solver jacobi (pre-stabilization and friction on), 96
  // substeps, twice from the same start: the contacts' slips saved at each substep's end from
  // the positions the iterations ended with where the device holds them (its whole-substep
  // call), and from those positions sent again (send_history_p). The same positions and
  // velocities every substep; the second sends exactly the positions more (12 B a grain) where
  // the substep was one call: with Chebyshev's step from substep 48 on too, which the call
  // makes there (host_chebyshev, its step made here between the iterations, leaves the
  // positions here, and both send them: nothing more).
  // (host_finish: the host predicts, pre-stabilizes and ends the substep, as send_history_p's
  // positions need; the chain that keeps those there is the test below's)
  test::Scene there = jacobi_block();
  there.s.host_finish = true;
  test::Scene sent = there;
  sent.s.send_history_p = true;
  const double n = double(there.size());
  for (int k = 0; k < 96; ++k) {
    for (test::Scene* sc : {&there, &sent}) {
      sc->s.chebyshev_rho = k < 48 ? 0.0f : 0.9f;
      sc->s.host_chebyshev = k >= 72;
    }
    const size_t saved = there.solver.histories_saved_on_device();
    const double more = twin_substep(there, sent).sent;
    INFO("substep " << k << ": " << more / n << " B a grain more sent");
    CHECK(there.solver.histories_saved_on_device() == saved + 1);
    CHECK(more == (k < 72 ? 12 * n : 0));
  }
}

TEST_CASE("use_opencl: the Jacobi path's pair sums stay on the device", "[opencl][jacobi]") {
  // The 512 falling grains with contact_solver jacobi, 120 substeps, twice from the same start:
  // the contacts' history made on the host (host_history), which reads each row entry's
  // accumulated normal correction (its pair sum, 4 B), so that they come back after the
  // iterations; and on the device, where they stay (they come back only for a rebuild of the
  // rows during the iterations or a history the device cannot make: GrainsSolver::sync_sums).
  // The two runs give the same positions every substep, and what the device's run receives is
  // the host's run's less exactly the pair sums and the collider planes, which stay there with
  // the history made there (jacobi_planes_stay): their rows (4 B a grain: the number of entries
  // alone comes back), their entries and colliders (40 B an entry) and the collider sums (4 B
  // an entry) the host's history reads.
  test::Scene there = jacobi_block();
  there.s.fetch_rows = true;  // as the host's history reads them
  there.s.host_finish = true;  // and the end made here, as the host's history needs
  test::Scene host = there;
  host.s.host_history = true;
  const double n = double(there.size());
  for (int k = 0; k < 120; ++k) {
    const double less = twin_substep(there, host).received;
    const double rows = double(there.solver.candidates()->indices.size());
    const double planes = double(there.solver.plane_entries());
    INFO("substep " << k << ": " << rows / n << " row entries a grain, " << less / n
                    << " B a grain less received");
    CHECK(rows > 0);
    CHECK(less == 4 * rows + 4 * n + 44 * planes);
  }
}
