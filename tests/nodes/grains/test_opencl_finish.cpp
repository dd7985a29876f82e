// The substep's end on the OpenCL device (gr_k_finish, opencl::SubstepEnd): the
// velocity update there, the final collision test there, its written positions kept there for
// error control's overlap statistics, and the grains the host's final collision test moves
// after it (a mesh collider whose queries the host makes) sent alone.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cfloat>
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

#include "engine/motion.h"
#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"

using namespace grains;

namespace {

// Ends one substep of `start` on the host (GrainsSettings::host_finish) and on the device, both
// from the same state, and checks that the two agree: the same solve, so the same solved
// positions; the device's velocity update (gr_update_velocity) writes them as the host does
// (the solved position plus the origin, or the start for a drifting grain: no arithmetic that
// rounds differently), so the written positions are the same bits, and so are error control's
// statistics of them, read where the device wrote them. The velocities may differ in their last
// bits: each side may fuse a multiply and an add where the other does not in the blend and the
// caps that follow the predicted velocity v + dt F / m (which both fuse, gr_fmadd), each a few
// roundings of |v_new| + |v_pred|: within 8 eps (|v_new| + |v| + dt |F| / m) of each other. Returns
// the grains the final collision test moved on the device; *rows_there: whether the statistics were
// read there.
size_t check_finish(const test::Scene& start, bool* rows_there = nullptr) {
  test::Scene host = start, device = start;
  host.s.host_finish = true;
  device.s.host_finish = false;
  host.substep();
  device.substep();
  REQUIRE(!host.solver.finished_on_device());
  REQUIRE(device.solver.finished_on_device());
  CHECK(host.P == device.P);
  const float dt = start.s.dt;
  size_t worse = 0;
  for (size_t i = 0; i < start.size(); ++i) {
    const Vec3 f =
        start.gravity * start.mass[i] + (start.extra_force.empty() ? Vec3{} : start.extra_force[i]);
    const float pull = start.mass[i] > 0 ? dt * length(f) / start.mass[i] : 0.0f;
    const float bound = 8 * FLT_EPSILON * (length(host.vel(i)) + length(start.vel(i)) + pull);
    if (length(host.vel(i) - device.vel(i)) > bound) ++worse;
  }
  CHECK(worse == 0);
  CHECK(host.stats.contacts == device.stats.contacts);
  CHECK(host.stats.max_penetration == device.stats.max_penetration);
  CHECK(host.stats.mean_penetration == device.stats.mean_penetration);
  // and so are the sleeping test's counts of near neighbours, read where the statistics took
  // the positions (the host's side sent all of them), when the device holds the rows (a copied
  // solver's device holds none until it searches again)
  const std::vector<uint8_t> fast(start.size(), 0);
  std::vector<uint32_t> host_words, device_words;
  const bool there =
      host.solver.sleep_rows_on_device(host.P.data(), false, fast.data(), &host_words);
  CHECK(device.solver.sleep_rows_on_device(device.P.data(), false, fast.data(), &device_words) ==
        there);
  CHECK(host_words == device_words);
  if (rows_there) *rows_there = there;
  return device.solver.finish_changed();
}

}  // namespace

TEST_CASE("use_opencl: the device ends the substep as the host does", "[opencl][gauss_seidel]") {
  // The contact-list tests' 512 grains falling onto the ground, ended on both sides after 30
  // substeps (in the fall, the lower layers landing) and after 90 (at rest): with gravity (one
  // force row for every grain), and in the fall with a force of each grain's own (a row a grain)
  // and with the velocity blended, capped in acceleration and speed, and a drift threshold, and
  // moved 96 m away along x and z (the substep's coordinates then have an origin of their own,
  // which the written positions add back: solver.cpp, local_origin); at
  // rest with the start velocity kept (error control's first finer substep: the device writes
  // the start's, the same bits, and its final collision test follows there).
  test::Scene sc = test::layered_block(true);
  int done = 0;
  for (const int settle : {30, 90}) {
    for (; done < settle; ++done) sc.substep();
    // (each copy opens a device of its own, a few seconds on PoCL: the variants that read what
    // moves in the fall, the force and the caps, are ended in it, the kept velocity at rest)
    for (const int variant : settle == 30 ? std::vector<int>{0, 1, 3, 4} : std::vector<int>{0, 2}) {
      test::Scene start = sc;
      if (variant == 1)
        for (size_t i = 0; i < start.size(); ++i)
          start.extra_force.push_back({0.1f * float(i % 7), 0.0f, -0.05f * float(i % 5)});
      if (variant == 2) start.s.keep_velocity = true;
      if (variant == 3) {
        start.s.velocity_blend = 0.3f;
        start.s.max_acceleration = 20.0f;
        start.s.max_speed = 1.5f;
        start.s.drift_threshold = 0.01f;
      }
      if (variant == 4)  // far from the world's origin: the substep works about another
        for (size_t i = 0; i < start.size(); ++i)
          start.P[3 * i] += 96.0f, start.P[3 * i + 2] += 96.0f;
      INFO("after " << settle << " substeps, variant " << variant);
      check_finish(start);
      if (variant == 2) {
        // the kept start velocity is written there as the host keeps it, bit for bit, and the
        // final collision test against the ground follows there, as in any other substep
        test::Scene host = start, device = start;
        host.s.host_finish = true;
        host.substep();
        device.substep();
        CHECK(device.solver.collided_on_device());
        CHECK(device.v == host.v);
        CHECK(device.P == host.P);
      }
    }
  }
}

TEST_CASE("use_opencl: the final collision test on the device and on the host after it",
          "[opencl][gauss_seidel]") {
  // 16 grains shot at 30 m/s at a plate thinner than their radius, each above a fixed grain
  // hanging under the plate: in one substep of 1/240 s a shot grain would move 0.125 m, through
  // the plate onto the fixed one, and the passes leave it just under the fixed grain (measured:
  // touching it). Only the final collision test's sweep sees that it came through and puts it
  // back on top, far from the fixed grain: pushed out to a radius from the plate's top face (less
  // a few float steps at 0.045 m, 1e-8 m; 1e-6 m allowed).
  //  - An analytic box plate: the device runs the test (gr_k_final_collision) on what it wrote,
  //    from the same functions as the host, so check_finish finds the host's positions, bit for
  //    bit, and nothing goes up after it.
  //  - The same plate as a triangle mesh (a closed one: a solid), whose queries the device makes
  //    too (engine/mesh_query.h, the functions MeshShape's own queries call): the same.
  //  - An open sheet instead, 1 cm under the shot grains' centres (a shell, which has no inside:
  //    a grain starting within r/2 of it leaves no trace to sweep, and only its path's crossing,
  //    gr_mesh_crossing, puts it back on the side it came from), its queries on the device too:
  //    the same.
  //  - The mesh plate with its queries made on the host (host_mesh, as a device without double
  //    precision has them): the host's test follows the device's end, and the 16 grains it moved
  //    go up alone for the statistics and the sleeping test's counts, which must be those of the
  //    positions the host holds. Without the statistics the sleeping test sends them.
  const float r = 0.04f, top = 0.005f;  // test::shot_plate's
  const char* const names[] = {"a box plate, ", "a mesh plate, ", "a sheet, ",
                               "a mesh plate, its queries on the host, "};
  for (const int variant : {0, 1, 2, 3}) {
    const bool mesh = variant > 0, mesh_here = variant == 3;
    test::Scene sc = test::shot_plate(mesh);
    const float face = variant == 2 ? 0.05f : top;  // the surface the grains stop on
    if (variant == 2) {
      std::string problem;
      sc.colliders[0].shape.mesh = MeshShape::build(test::quad_mesh(1.0f, face), &problem);
      REQUIRE(!sc.colliders[0].shape.mesh->closed());
    }
    sc.s.host_mesh = mesh_here;
    REQUIRE((!mesh || sc.colliders[0].shape.mesh));
    for (const bool with_stats : {true, false}) {
      INFO(names[variant] << (with_stats ? "with" : "without") << " the overlap statistics");
      sc.with_stats = with_stats;
      bool there = false;
      test::Scene end = sc;
      end.s.host_finish = false;
      end.substep();
      CHECK(end.solver.collided_on_device() == !mesh_here);
      for (size_t i = 0; i < sc.size(); i += 2) CHECK(end.P[3 * i + 1] > face + r - 1e-6f);
      const size_t moved = check_finish(sc, &there);
      INFO(moved << " grains moved by the host's final collision test after the device's end");
      CHECK(moved == (mesh_here ? 16u : 0u));
      CHECK(there);
    }
  }
}

TEST_CASE("use_opencl: the substep's start made on the device from the last end",
          "[opencl][gauss_seidel]") {
  // The contact-list tests' 512 grains falling onto the ground for 60 substeps, twice: every
  // start sent whole (resend_start), and made on the device from what the last substep's end
  // wrote there, with only the grains whose host floats differ sent. Between substeps something
  // else changes some grains, as another node or the sleeping test would: every 7th substep 13
  // grains' velocities, every 11th 9 grains' positions (1 mm up); from the 30th substep on the
  // grains lie 96 m from the world's origin along x and z and fall from 64 m up (the start's
  // origin then changes along every axis: the device subtracts it as the host does). The
  // device's start is then the host's floats, so the two runs must end with the same positions
  // and velocities, bit for bit; the start is made there on every substep after the first but
  // the one after the move (every grain differs), and only the grains changed since the last
  // end go up (none between unchanged substeps).
  test::Scene sent = test::layered_block(true), made = sent;
  sent.s.resend_start = true;
  size_t carried = 0, patched = 0;  // substeps whose start was made there; grains sent for them
  for (int k = 0; k < 60; ++k) {
    size_t changed = 0;
    if (k == 30) {
      for (test::Scene* sc : {&sent, &made})
        for (size_t i = 0; i < sc->size(); ++i)
          sc->P[3 * i] += 96.0f, sc->P[3 * i + 1] += 64.0f, sc->P[3 * i + 2] += 96.0f;
      changed = sent.size();
    } else {
      const bool kick = k % 7 == 3, lift = k % 11 == 5;
      for (test::Scene* sc : {&sent, &made})
        for (size_t i = 0; i < sc->size(); ++i) {
          if (kick && i % 37 == 0) sc->set_vel(i, sc->vel(i) + Vec3{0.1f, 0.2f, 0.0f});
          if (lift && i % 53 == 1) sc->P[3 * i + 1] += 0.001f;
        }
      for (size_t i = 0; i < sent.size(); ++i)
        changed += (kick && i % 37 == 0) || (lift && i % 53 == 1);
    }
    sent.substep();
    made.substep();
    INFO("substep " << k);
    CHECK(!sent.solver.carried_start());
    CHECK(made.solver.carried_start() == (k > 0 && k != 30));
    if (k > 0 && k != 30) CHECK(made.solver.carried_changed() == changed);
    if (made.solver.carried_start()) ++carried, patched += changed;
  }
  CHECK(sent.P == made.P);
  CHECK(sent.v == made.v);
  // and what crosses: the same but for the start of each substep made there, whose 24 bytes a
  // grain (position and velocity, neither one value over and over in this fall) did not go up,
  // and for which each changed grain went up alone, 28 bytes (index, position, velocity): to the
  // byte
  const double saved =
      double(sent.solver.device_traffic().sent) - double(made.solver.device_traffic().sent);
  INFO("sent " << saved / (60.0 * double(sent.size())) << " bytes a grain a substep less");
  CHECK(saved == 24.0 * double(sent.size() * carried) - 28.0 * double(patched));
}

// 512 grains falling onto the ground, each grain with a mass of its own and a force of its own
// on top of its weight (so that dt F / m rounds differently from grain to grain), run twice for
// `substeps` substeps: `sent` with the host's predicted positions sent every substep
// (host_predict), `made` with the device's; each(sent, made) after every substep.
namespace {
struct FallTwice {
  test::Scene sent, made;
};
FallTwice fall_twice(int substeps,
                     const std::function<void(const test::Scene&, const test::Scene&)>& each) {
  FallTwice f{test::layered_block(true), test::Scene{}};
  for (size_t i = 0; i < f.sent.size(); ++i) {
    f.sent.mass[i] = 0.5f + 0.37f * float(i % 5);
    f.sent.extra_force.push_back({0.3f * float(i % 7) - 0.9f, 0.11f * float(i % 3), 0.7f});
  }
  f.made = f.sent;
  f.sent.s.host_predict = true;
  for (int k = 0; k < substeps; ++k) {
    f.sent.substep();
    f.made.substep();
    INFO("substep " << k);
    each(f.sent, f.made);
  }
  return f;
}
}  // namespace

TEST_CASE("use_opencl: the substep's prediction made on the device", "[opencl][gauss_seidel]") {
  // The same 512 grains falling onto the ground for 40 substeps, each grain with a mass of its
  // own and a force of its own on top of its weight (so that dt F / m rounds differently from
  // grain to grain), twice: the host's predicted positions sent every substep (host_predict),
  // and made on the device from the start, velocities, masses and force it holds. The device
  // makes the host's floats (both fuse p = P + dt (v + dt F / m), gr_fmadd), and the search of
  // rows, the planes and the solve take them there, so the two runs end with the same positions
  // and velocities, bit for bit, and the second sends exactly 12 bytes a grain a substep less:
  // the predicted positions, which went up once a substep with the search of rows, or with the
  // planes when the substep kept its rows.
  const int substeps = 40;
  FallTwice f = fall_twice(substeps, [](const test::Scene& sent, const test::Scene& made) {
    CHECK(!sent.solver.predicted_on_device());
    CHECK(made.solver.predicted_on_device());
  });
  const test::Scene &sent = f.sent, &made = f.made;
  CHECK(made.solver.contact_lists_kept() > 0);  // kept rows: the planes took the predictions
  CHECK(sent.P == made.P);
  CHECK(sent.v == made.v);
  const double saved =
      double(sent.solver.device_traffic().sent) - double(made.solver.device_traffic().sent);
  CHECK(saved == 12.0 * double(sent.size()) * substeps);
}

TEST_CASE("use_opencl: the Verlet test of kept rows made on the device", "[opencl][gauss_seidel]") {
  // The same fall twice: the host's predicted positions made and sent every substep
  // (host_predict), whose Verlet test the host makes against the positions its rows were built
  // from, and the device's prediction, tested there against the positions its search took. Both
  // sides compute the largest move unfused (gr_rows_moved), so they keep and rebuild the rows in
  // the same substeps and end with the same positions and velocities, bit for bit; and the
  // second run's host makes no prediction at all: no stage reads one here (the search, the
  // planes, the solve and the end are the device's).
  const int substeps = 40;
  FallTwice f = fall_twice(substeps, [](const test::Scene&, const test::Scene&) {});
  test::Scene &sent = f.sent, &made = f.made;
  CHECK(sent.solver.host_predictions() == size_t(substeps));
  CHECK(made.solver.host_predictions() == 0);
  CHECK(sent.solver.rows_tests_on_device() == 0);
  // every substep but the first tested the rows there: kept, or rebuilt (in the same substeps)
  const size_t searched = made.solver.rows_left_on_device();
  CHECK(sent.solver.rows_left_on_device() == searched);
  CHECK(made.solver.rows_tests_on_device() == size_t(substeps - 1));
  CHECK(searched > 1);
  CHECK(searched < size_t(substeps));
  CHECK(sent.P == made.P);
  CHECK(sent.v == made.v);
  // a copy of the solver takes the rows' positions from the device, and goes on alike
  test::Scene copy = made;
  for (int k = 0; k < 10; ++k) {
    made.substep();
    copy.substep();
    sent.substep();
  }
  CHECK(copy.P == made.P);
  CHECK(sent.P == made.P);
}

TEST_CASE("use_opencl: the substep's end held on the device and the next substep started there",
          "[opencl][gauss_seidel]") {
  // The contact-list tests' 512 grains falling onto the ground for 60 substeps, twice: each
  // end brought back (`fetched`), and each held on the device (GrainsData::may_hold_end), the
  // next substep started there (start_held), the host's positions and velocities NaN in
  // between (a stage that read them here would spread NaN). Every fifth held end is brought
  // back (end_positions, end_velocities) and must be the fetched run's, bit for bit; at the
  // 30th substep the grains move 96 m along x and z and 64 m up (a start the host sends, whose
  // origin differs; the held ends after it take theirs from the box the device measures).
  test::Scene fetched = test::layered_block(true), held = fetched;
  held.hold_end = true;
  const size_t n = held.size();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  size_t checked = 0, not_brought = 0;
  for (int k = 0; k < 60; ++k) {
    INFO("substep " << k);
    if (k == 30) {
      // the held end comes back, and moves, as another node would move it
      std::copy_n(held.solver.end_positions(), 3 * n, held.P.begin());
      std::copy_n(held.solver.end_velocities(), 3 * n, held.v.begin());
      for (test::Scene* sc : {&fetched, &held})
        for (size_t i = 0; i < n; ++i)
          sc->P[3 * i] += 96.0f, sc->P[3 * i + 1] += 64.0f, sc->P[3 * i + 2] += 96.0f;
      held.hold_end = false;
      held.substep();
      held.hold_end = true;
    } else {
      if (held.solver.end_held()) std::fill(held.P.begin(), held.P.end(), nan), held.v = held.P;
      held.substep();
    }
    fetched.substep();
    REQUIRE(held.solver.end_held() == (k != 30));
    if (k == 30) {
      CHECK(held.P == fetched.P);
      CHECK(held.v == fetched.v);
    } else if (k % 5 == 4 || k == 59) {
      const std::vector<float> P(held.solver.end_positions(), held.solver.end_positions() + 3 * n);
      const std::vector<float> v(held.solver.end_velocities(),
                                 held.solver.end_velocities() + 3 * n);
      CHECK(P == fetched.P);
      CHECK(v == fetched.v);
      ++checked;
    } else {
      ++not_brought;
    }
    CHECK(held.stats.contacts == fetched.stats.contacts);
    CHECK(held.stats.mean_penetration == fetched.stats.mean_penetration);
  }
  CHECK(checked == 12);
  CHECK(held.solver.held_ends() == 59);
  // not the first, the moved one or the one after it (the moved one's end came back)
  CHECK(held.solver.held_starts() == 57);
  // what crosses: the 24 bytes a grain of each end not brought back did not, but each held end's
  // box (28 bytes a work-item, n / 64 of them in whole work-groups of 64)
  const double saved = double(fetched.solver.device_traffic().received) -
                       double(held.solver.device_traffic().received);
  INFO("received " << saved / (60.0 * double(n)) << " bytes a grain a substep less");
  CHECK(saved == 24.0 * double(n * not_brought) - 28.0 * 64.0 * 59.0);
}

TEST_CASE("use_opencl: an end that is not finite is not held on the device", "[opencl]") {
  // The falling 512 grains' first substep, whose end the device holds, and the same with one
  // grain thrown at an infinite speed: its end is not finite, so the end comes back for the
  // caller to find it (the engine names the grain)
  test::Scene sc = test::layered_block(true), thrown = sc;
  sc.hold_end = thrown.hold_end = true;
  thrown.set_vel(100, {std::numeric_limits<float>::infinity(), 0.0f, 0.0f});
  sc.substep();
  thrown.substep();
  CHECK(sc.solver.end_held());
  CHECK_FALSE(thrown.solver.end_held());
  CHECK_FALSE(std::isfinite(thrown.pos(100).x));
}

TEST_CASE("use_opencl: the substep's start made on the device from an end in another order",
          "[opencl][gauss_seidel]") {
  // The contact-list tests' 512 grains, with ids, falling onto the ground for 40 substeps,
  // twice: every start sent whole (resend_start), and made on the device from the last end. At
  // every 10th substep the grains come in a new order (the grains node sorts them by cell at
  // each frame's first substep), at the 25th 13 grains are killed and 13 born in the air: each
  // grain is then found in the last end by its id and only the new ones go up, with each
  // grain's index in the end (4 bytes a grain) instead of every grain's start position and
  // velocity (24). The two runs end with the same positions and velocities, bit for bit.
  test::Scene sent = test::layered_block(true), made = sent;
  for (test::Scene* sc : {&sent, &made})
    for (size_t i = 0; i < sc->size(); ++i) sc->ids.push_back(int32_t(1000 + 3 * i));
  sent.s.resend_start = true;
  size_t reordered = 0, born_total = 0;
  for (int k = 0; k < 40; ++k) {
    INFO("substep " << k);
    const size_t n = made.size();
    std::vector<size_t> order;
    size_t born = 0;
    if (k > 0 && k % 10 == 0) {
      order = test::blocks_reversed(n);
    } else if (k == 25) {
      order = test::killed_and_born(n, &born);
    }
    if (!order.empty())
      for (test::Scene* sc : {&sent, &made}) test::reorder(*sc, order, {0.1f, 1.2f, 0.1f});
    sent.substep();
    made.substep();
    CHECK(made.solver.carried_start() == (k > 0));
    if (!order.empty() && k != 25) CHECK(made.solver.carried_changed() == 0);
    if (k == 25) CHECK(made.solver.carried_changed() == born);
    if (!order.empty()) ++reordered, born_total += born;
    REQUIRE(sent.P == made.P);
    REQUIRE(sent.v == made.v);
  }
  CHECK(reordered == 4);
  CHECK(born_total == 13);
  // what is sent less: 24 bytes a grain at every start made there but for the 28 of each grain
  // sent alone, less the 4 bytes a grain of each reordered start's indices
  const double saved =
      double(sent.solver.device_traffic().sent) - double(made.solver.device_traffic().sent);
  CHECK(saved == 24.0 * 512.0 * 39.0 - 28.0 * double(born_total) - 4.0 * 512.0 * double(reordered));
}

TEST_CASE(
    "use_opencl: error control's motion measure of a held end made on the device is the host's",
    "[opencl][gauss_seidel]") {
  // The 512 falling grains, each end held on the device, for 40 substeps: the device's measure
  // of the end (GrainsSolver::motion_on_device, engine/motion_need.h) against the host's over
  // the same end brought back (engine/motion.h, motion_need), the largest need and the largest
  // acceleration over radius the same doubles, bit for bit, at gauss_seidel's step (r / 4) and
  // the default (r / 2), with one force for all and, from the 20th substep, a force of its own
  // for each grain and masses that differ.
  test::Scene sc = test::layered_block(true);
  sc.hold_end = true;
  const size_t n = sc.size();
  const double fps = 24;
  size_t measured = 0, moving = 0;  // measures that ask for more than one substep a frame
  for (int k = 0; k < 40; ++k) {
    INFO("substep " << k);
    if (k == 20) {
      if (sc.solver.end_held()) {
        std::copy_n(sc.solver.end_positions(), 3 * n, sc.P.begin());
        std::copy_n(sc.solver.end_velocities(), 3 * n, sc.v.begin());
      }
      sc.extra_force.resize(n);
      for (size_t i = 0; i < n; ++i) {
        sc.mass[i] = 1.0f + 0.25f * float(i % 5);
        sc.extra_force[i] = Vec3{0.3f * float(i % 7) - 0.9f, 0.0f, 0.1f * float(i % 3)};
      }
    }
    sc.substep();
    REQUIRE(sc.solver.end_held());
    for (const double step : {0.25, 0.5}) {
      MotionBounds bounds;
      bounds.step = step;
      double worst = 1, fall = 0;
      REQUIRE(sc.solver.motion_on_device(step, fps, &worst, &fall));
      ParticleStore pts;
      pts.add_points(n);
      std::copy_n(sc.solver.end_positions(), 3 * n, pts.v3("P"));
      std::copy_n(sc.solver.end_velocities(), 3 * n, pts.v3("v"));
      std::copy_n(sc.force.data(), 3 * n, pts.v3("force"));
      std::copy_n(sc.mass.data(), n, pts.f("mass"));
      std::copy_n(sc.pscale.data(), n, pts.f("pscale"));
      std::fill_n(pts.i("ispbd"), n, 1);
      double host_worst = 1, host_fall = 0;
      REQUIRE(motion_need(pts, fps, bounds, &host_worst, &host_fall));
      CHECK(worst == host_worst);
      CHECK(fall == host_fall);
      moving += worst > 1.0;
      ++measured;
    }
  }
  CHECK(sc.solver.motions_on_device() == measured);
  CHECK(moving > measured / 2);
}

TEST_CASE("use_opencl: the Jacobi substep runs on the device from its prediction to its end",
          "[opencl][jacobi]") {
  // The contact-list tests' 512 grains falling onto the ground with contact_solver jacobi
  // (pre-stabilization and friction on), 90 substeps, twice: predicted, pre-stabilized and
  // ended on the host (host_finish), the device running the iterations alone; and the whole
  // substep chained on the device (GrainsSolver::jacobi_on_device): its prediction, the
  // pre-stabilization that moves the start and the prediction there, the iterations taking
  // those there, and the end there, held (GrainsData::may_hold_end) and the next substep
  // started from it, the host's positions and velocities NaN in between. The velocity update
  // is the same arithmetic on both sides (no blend nor cap acts here: kernels/velocity.h), so
  // every fifth held end, brought back, is the host's run's, bit for bit, and so is the count
  // of touching pairs every substep.
  test::Scene host = test::layered_block(true), held;
  host.s.contact_solver = kContactJacobi;
  host.s.pre_stabilization = true;
  held = host;
  host.s.host_finish = true;
  held.hold_end = true;
  const size_t n = held.size();
  const double grains = double(n), colliders = double(held.colliders.size());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  size_t checked = 0, stabilized = 0;
  for (int k = 0; k < 90; ++k) {
    INFO("substep " << k);
    if (held.solver.end_held()) std::fill(held.P.begin(), held.P.end(), nan), held.v = held.P;
    const opencl::Traffic held0 = held.solver.device_traffic(),
                          host0 = host.solver.device_traffic();
    held.substep();
    host.substep();
    const double held_sent = double(held.solver.device_traffic().sent - held0.sent);
    const double host_sent = double(host.solver.device_traffic().sent - host0.sent);
    REQUIRE(held.solver.finished_on_device());
    REQUIRE(!host.solver.finished_on_device());
    REQUIRE(held.solver.end_held());
    stabilized += held.solver.stabilize_passes() > 0;
    if (k % 5 == 4 || k == 89) {
      const std::vector<float> P(held.solver.end_positions(), held.solver.end_positions() + 3 * n);
      const std::vector<float> v(held.solver.end_velocities(),
                                 held.solver.end_velocities() + 3 * n);
      CHECK(P == host.P);
      CHECK(v == host.v);
      ++checked;
    }
    // (the mean: measured on the device, or on the host where the rows came back for the host's
    // run; each pair's overlap over its summed radii, (r - |d|) / r with |d| < r, from a length
    // whose squares either side may fuse differently, is within 2 eps of the other side's, and
    // so is their mean, plus the roundings of the sum and the float it is written as)
    CHECK(held.stats.contacts == host.stats.contacts);
    CHECK(std::fabs(held.stats.max_penetration - host.stats.max_penetration) <= 2 * FLT_EPSILON);
    CHECK(std::fabs(held.stats.mean_penetration - host.stats.mean_penetration) <= 4 * FLT_EPSILON);
    // What goes up after the first substep: no position. The chain sends at most, a grain, the
    // ids for a lookup of the contacts' slips (8 B, where the grains' order changed), 136 B a
    // collider, 12 for the force and 1 KiB of flags and sums (the planes' carried slips are made
    // there: jacobi_planes_stay); the host's run sends, a
    // grain, the predicted positions for the search (12 B), the start and pre-stabilization's
    // own copy of it (24), and the pre-stabilized start and the predicted positions it moved,
    // for the iterations (24).
    if (k > 0) {
      INFO("sent " << held_sent / grains << " B a grain, the host's run " << host_sent / grains);
      CHECK(held_sent <= 8 * grains + 136 * colliders + 12 + 1024);
      CHECK(host_sent >= 60 * grains);
    }
  }
  CHECK(checked == 18);
  CHECK(stabilized >= 80);
  CHECK(held.solver.held_ends() == 90);
  CHECK(held.solver.held_starts() == 89);
  // the device predicted every substep, the host none of them
  CHECK(held.solver.host_predictions() == 0);
  CHECK(host.solver.host_predictions() == 90);
}

TEST_CASE("use_opencl: Chebyshev's step made on the device within the Jacobi substep",
          "[opencl][jacobi]") {
  // The 512 falling grains with contact_solver jacobi (pre-stabilization and friction on, 8 x
  // 10) and chebyshev_rho 0.9, 60 substeps, twice: the step made on the host between the
  // iterations, each a device call of its own (host_chebyshev), the positions going up and
  // coming back at each; and made there, after each iteration of the substep's one call
  // (kernels/iterate.h, gr_k_chebyshev), the substep chained there from its prediction to its
  // end. Both make the step with one rounding a component (gr_fmadd), so the two runs end every
  // substep with the same positions and velocities, bit for bit, with the friction pass once
  // after the iterations and after each of them (accurate_friction).
  for (bool accurate : {false, true}) {
    INFO("accurate_friction " << accurate);
    test::Scene host = test::layered_block(true), there;
    host.s.contact_solver = kContactJacobi;
    host.s.pre_stabilization = true;
    host.s.chebyshev_rho = 0.9f;
    host.s.accurate_friction = accurate;
    there = host;
    host.s.host_chebyshev = true;
    const double n = double(there.size());
    for (int k = 0; k < 60; ++k) {
      INFO("substep " << k);
      const opencl::Traffic there0 = there.solver.device_traffic(),
                            host0 = host.solver.device_traffic();
      host.substep();
      there.substep();
      REQUIRE(host.P == there.P);
      REQUIRE(host.v == there.v);
      CHECK(there.solver.finished_on_device());
      CHECK(!host.solver.finished_on_device());
      // each of the host's 10 iterations sends the positions (12 B a grain) and brings them
      // back; the chain sends no position after the first substep (its bound: the test above)
      const double there_sent = double(there.solver.device_traffic().sent - there0.sent);
      const double host_sent = double(host.solver.device_traffic().sent - host0.sent);
      INFO("sent " << there_sent / n << " B a grain, the host's step's run " << host_sent / n);
      CHECK(host_sent >= 120 * n);
      if (k > 0) CHECK(there_sent <= 8 * n + 136 * double(there.colliders.size()) + 12 + 1024);
    }
  }
}
