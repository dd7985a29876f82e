// Physics tests of the grains PBD solver (DESIGN §4, the POP Grains help page). Each test states
// the law or closed form it checks and derives its tolerance from the physics of the scheme.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstring>

#include "engine/geometry_io.h"
#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"

using namespace grains;
using namespace grains::test;

namespace {

// A vertical column of `count` touching grains of radius r standing on the ground at y = 0.
Scene column(int count, float r, const GrainsSettings& s) {
  Scene sc;
  sc.s = s;
  sc.add_collider(ground());
  for (int k = 0; k < count; ++k) sc.add({0, r + 2 * r * k, 0}, r);
  return sc;
}

}  // namespace

TEST_CASE("a column of 50 grains stands at 50 diameters with enough iterations", "[grains]") {
  // Resting column: the top centre belongs at 49 * 2r + r. Each substep gravity moves every grain
  // down by delta = g dt^2 and the Jacobi iterations must carry the ground's push up the chain.
  // A pair splits its correction (share 1/2) and a grain averages its two contacts (1/2), so an
  // interior grain moves by (o_below - o_above) / 4 per iteration; in steady state the I
  // iterations of a substep must lift every grain by delta, so overlaps grow by 4 delta / I per
  // grain going down and the column sags by ~ 2 delta N^2 / I. N = 50, I = 100, dt = 1/120 s:
  // delta = 6.8e-4 m, sag ~ 0.034 m = 0.7% of 4.95 m, inside 1%. With I = 10 the estimate is
  // ~ 7%: the column must sag by more than 1%. That is the Jacobi average's count (contact_solver
  // jacobi, POP Grains'); the default gauss_seidel carries each contact's load from substep to
  // substep, and the stacks at the node defaults have their own test.
  const float r = 0.05f;
  const float expected = 49 * 2 * r + r;
  GrainsSettings jacobi = settings(24, 5, 100);
  jacobi.contact_solver = kContactJacobi;
  Scene good = column(50, r, jacobi);
  good.run(3.0f);
  float err = std::fabs(good.max_y() - expected) / expected;
  report("column 50, 5 substeps x 100 iterations: relative height error", err);
  CHECK(err < 0.01f);

  jacobi.constraint_iterations = 10;
  Scene poor = column(50, r, jacobi);
  poor.run(3.0f);
  float sag = (expected - poor.max_y()) / expected;
  report("column 50, 5 substeps x 10 iterations: relative sag", sag);
  CHECK(sag > 0.01f);
}

TEST_CASE("a grain on a frictionless incline accelerates at g sin(theta)", "[grains][friction]") {
  // No friction: the plane contact removes only the normal part of each substep's motion, so
  // the tangential motion is exactly free fall projected on the plane, a = g sin(theta). The
  // only error is float rounding and the projection, far below 2%.
  const float deg = 30.0f, th = deg * static_cast<float>(M_PI) / 180.0f;
  const float r = 0.05f;
  Scene sc;
  sc.s = settings(24, 4, 10);
  sc.s.friction_with_colliders = 0;
  sc.add_collider(incline(deg));
  Vec3 n{-std::sin(th), std::cos(th), 0};
  sc.add(n * r, r);
  const float t = 1.0f;
  sc.run(t);
  Vec3 down{-std::cos(th), -std::sin(th), 0};
  float s_along = dot(sc.pos(0) - n * r, down);
  float a = 2 * s_along / (t * t);
  // semi-implicit Euler: distance after k substeps is g sin dt^2 k (k+1)/2, i.e. a*(1 + dt/t)
  float a_expected = kG * std::sin(th) * (1 + sc.s.dt / t);
  report("frictionless incline: a / (g sin theta)", a / (kG * std::sin(th)));
  CHECK(std::fabs(a - a_expected) / a_expected < 0.02f);
  // it stays on the plane: the normal distance is r (contact resolved exactly)
  CHECK(std::fabs(dot(sc.pos(0), n) - r) < 1e-4f);
}

namespace {

// A small block of 3 x 2 x 3 grains resting on an incline of `deg` degrees; returns how far its
// centroid moved along the plane in `seconds`.
float block_slide(float deg, const GrainsSettings& s, float seconds = 1.0f) {
  const float r = 0.05f, th = deg * static_cast<float>(M_PI) / 180.0f;
  Scene sc;
  sc.s = s;
  sc.add_collider(incline(deg));
  Vec3 n{-std::sin(th), std::cos(th), 0};
  Vec3 u{std::cos(th), std::sin(th), 0};  // up the slope
  Vec3 w{0, 0, 1};
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 2; ++b)
      for (int c = 0; c < 3; ++c)
        sc.add(u * (2 * r * a) + n * (r + 2 * r * b) + w * (2 * r * c), r);
  Vec3 c0 = sc.centroid();
  sc.run(seconds);
  return length(sc.centroid() - c0);
}

// A grain on an incline collider 2 degrees either side of atan(static_threshold x friction),
// with the contact solver given.
void check_sticking(ContactSolver solver) {
  // Coulomb law of Macklin's friction: per substep a resting grain slips g sin dt^2 along the
  // plane and sinks g cos dt^2 into it; the friction scale multiplies that bound, so it sticks
  // while tan(theta) < mu = static_threshold x friction_with_colliders, exactly, from the first
  // substep on. 2 degrees either side of atan(mu): it stays put (< 1 um, rounding) or slides
  // (g (sin - mu_k cos) >= 0.05 m/s^2 for mu_k = 0.5 mu: > 2 cm in 1 s).
  const float r = 0.05f;
  for (float st : {0.5f, 1.0f})
    for (float fc : {0.25f, 0.5f, 1.0f}) {
      float crit = std::atan(st * fc) * 180.0f / static_cast<float>(M_PI);
      for (float deg : {crit - 2, crit + 2}) {
        float th = deg * static_cast<float>(M_PI) / 180.0f;
        Scene sc;
        sc.s = settings(24, 2, 10);
        sc.s.contact_solver = solver;
        sc.s.static_threshold = st;
        sc.s.friction_with_colliders = fc;
        sc.add_collider(incline(deg));
        Vec3 n{-std::sin(th), std::cos(th), 0};
        sc.add(n * r, r);
        sc.run(1.0f);
        float moved = length(sc.pos(0) - n * r);
        INFO("static_threshold " << st << " friction " << fc << " angle " << deg);
        if (deg < crit)
          CHECK(moved < 1e-6f);
        else
          CHECK(moved > 0.02f);
      }
    }
}

}  // namespace

TEST_CASE("a grain sticks below atan(static_threshold x friction) and slides above",
          "[grains][friction]") {
  check_sticking(kContactJacobi);
}

TEST_CASE("with the contacts one at a time, a grain sticks below atan(mu_s) and slides above",
          "[grains][friction][gauss_seidel]") {
  // contact_solver gauss_seidel: the plane's own Coulomb cone, bounded by the normal correction
  // it applied in the substep (and carried from the last), the same law
  check_sticking(kContactGaussSeidel);
}

TEST_CASE("a block's sliding angle rises with collider friction", "[grains][friction]") {
  // A two-layer block with accurate friction (the mode that stacks grains, help page). It sticks
  // (creeps < 1 cm/s from the Jacobi averaging) or slides (accelerating, tens of cm in 1 s).
  // Scanning 7.5, 12.5, ... degrees, the first sliding angle must rise with friction and stay
  // near a single grain's Coulomb angle atan(mu) (a lone grain meets it exactly: the scan above).
  // A bottom grain's friction pools the bounds of its slipping contacts (gr_friction_pass), and
  // in the Jacobi iterations the upper layer's grains slip on it too, so their normal corrections
  // add to the bound it holds the ground with: the block holds 8-11 degrees past atan(mu)
  // (22.5 and 37.5 degrees at friction 0.25 and 0.5, measured), under the 12 degrees allowed
  // here, never twice the angle's tangent.
  auto threshold = [](float fc) {
    GrainsSettings s = settings(24, 2, 20);
    s.accurate_friction = true;
    s.friction_with_colliders = fc;
    for (float deg = 7.5f; deg <= 60; deg += 5)
      if (block_slide(deg, s) > 0.01f) return deg;
    return 90.0f;
  };
  float t1 = threshold(0.25f), t2 = threshold(0.5f), t3 = threshold(1.0f);
  report("block sliding threshold (deg), friction 0.25 (atan 14.0)", t1);
  report("block sliding threshold (deg), friction 0.5 (atan 26.6)", t2);
  report("block sliding threshold (deg), friction 1 (atan 45)", t3);
  CHECK(t1 < t2);
  CHECK(t2 < t3);
  CHECK(t1 <= 14.04f + 12);
  CHECK(t2 <= 26.57f + 12);
  CHECK(t3 <= 45.0f + 12);
}

TEST_CASE("accurate friction holds a stacked block that single-pass friction lets slide",
          "[grains][friction]") {
  // Help page: accurate friction "is stronger and more accurate ... better able to stack
  // grains". A two-layer block at 20 degrees (atan 0.36, under mu = 1): with friction in every
  // iteration the layers lock and it creeps < 1 cm in 1 s; with one pass after the loop the
  // upper layer's slip reaches the lower one only once per substep and the block moves > 5 cm.
  GrainsSettings s = settings(24, 2, 20);
  s.contact_solver = kContactJacobi;  // accurate_friction is the Jacobi path's
  s.accurate_friction = true;
  float held = block_slide(20, s);
  s.accurate_friction = false;
  float slid = block_slide(20, s);
  report("2-layer block at 20 deg: displacement, accurate friction", held);
  report("2-layer block at 20 deg: displacement, single friction pass", slid);
  CHECK(held < 0.01f);
  CHECK(slid > 0.05f);
}

TEST_CASE("contact_memory stops a resting block's creep", "[grains][friction]") {
  // Coulomb friction holds a block below its friction angle (atan 0.5 = 26.6 degrees) without
  // moving. The Jacobi iterations leave part of each substep's slip unremoved; contact history
  // remembers it (up to contact_memory x the static coefficient x the summed radii) and pulls
  // it back in later substeps. Measured on a 3 x 2 x 3 block of 5 cm grains over 2 s: with the
  // default memory it moves 0.03-0.06 mm at 15 and 20 degrees, with none 0.8-1.1 mm. Asserted:
  // under 0.1 mm (0.2% of a radius) with memory, over 0.5 mm without.
  for (float deg : {15.0f, 20.0f}) {
    GrainsSettings s = settings(24, 2, 20);
    s.contact_solver = kContactJacobi;  // gauss_seidel carries whole loads instead
    s.friction_with_colliders = 0.5f;
    s.friction_with_particles = 0.5f;
    const float held = block_slide(deg, s, 2.0f);
    s.contact_memory = 0;
    const float crept = block_slide(deg, s, 2.0f);
    // gauss_seidel (the default) carries each contact's whole load instead: no creep either
    s.contact_solver = kContactGaussSeidel;
    const float carried = block_slide(deg, s, 2.0f);
    INFO(deg << " degrees");
    report("block displacement in 2 s, default contact_memory", held);
    report("block displacement in 2 s, contact_memory 0", crept);
    report("block displacement in 2 s, gauss_seidel", carried);
    CHECK(held < 1e-4f);
    CHECK(crept > 5e-4f);
    CHECK(carried < 1e-4f);
  }
}

TEST_CASE("kinetic friction decelerates a sliding grain at scale_kinetic x g", "[grains][friction]") {
  // On flat ground a grain sliding at v sinks g dt^2 per substep and slips v dt > static bound,
  // so the friction pass removes scale_kinetic x friction x g dt^2 of slip: Coulomb kinetic
  // friction, deceleration a = mu_k g, stopping distance v0^2 / (2 a). Discretisation: the last
  // substeps (v < static_threshold g dt, then it sticks) and the first shift the distance by
  // about v0 dt, 2 cm at v0 = 2 m/s, dt = 1/96 s: tolerance 0.03 m.
  for (float sk : {0.25f, 0.5f}) {
    Scene sc;
    sc.s = settings(24, 4, 10);
    sc.s.scale_kinetic = sk;
    sc.add_collider(ground());
    sc.add({0, 0.05f, 0}, 0.05f, 1, {2, 0, 0});
    sc.run(2.0f);
    float expected = 2.0f * 2.0f / (2 * sk * kG);
    report(sk < 0.3f ? "stopping distance, scale_kinetic 0.25 (0.815 m)"
                     : "stopping distance, scale_kinetic 0.5 (0.408 m)",
           sc.pos(0).x);
    CHECK(std::fabs(sc.pos(0).x - expected) < 0.03f);
    CHECK(length(sc.vel(0)) < 1e-4f);
  }
}

TEST_CASE("particle friction grows with overlap: soft contacts rub longer", "[grains][friction]") {
  // Friction is bounded by overlap (help page). Two grains overlapping by 10% of r_i + r_j slide
  // past each other at 1 m/s in zero gravity. Stiff contacts separate them within the first
  // substep, so friction acts once (bound ~ the 1 cm overlap: kinetic, removes about half the
  // slip); soft contacts (stiffness 2: 5% of the overlap per iteration) keep them overlapping
  // for many substeps and friction keeps acting, so the relative tangential speed must end
  // well below the stiff case's. This is the Jacobi path's law (POP Grains'), where a
  // contact's friction is bounded by the overlap it still has.
  auto slip_speed = [](float stiffness, ContactSolver solver) {
    Scene sc;
    sc.s = settings(24, 2, 20);
    sc.s.contact_solver = solver;
    sc.s.internal_collisions_stiffness = stiffness;
    sc.s.pre_stabilization = false;  // the overlap they start with is the point
    sc.gravity = {0, 0, 0};
    sc.add({0, 0, 0}, 0.05f);
    sc.add({0, 0.09f, 0}, 0.05f, 1, {1, 0, 0});
    sc.run(0.25f);
    return std::fabs(sc.vel(1).x - sc.vel(0).x);
  };
  float stiff = slip_speed(1000, kContactJacobi), soft = slip_speed(2, kContactJacobi);
  report("relative slip speed after 0.25 s, stiff contacts", stiff);
  report("relative slip speed after 0.25 s, soft contacts", soft);
  CHECK(stiff > 0.2f);
  CHECK(soft < 0.5f * stiff);
  // gauss_seidel (the default) bounds a contact's friction by the normal load it applied
  // (Coulomb, impulse for impulse): over the run the relative tangential speed can lose at most
  // mu_s x the normal speed the contacts gave, and pushing out the 1 cm overlap (pre-stabilization
  // off) gives at most 0.01 m / dt = 0.48 m/s however many substeps it takes, so with mu_s 1 the
  // slip ends above 0.52 m/s at any stiffness (the Jacobi path's soft pair ends at 0: its bound
  // is the overlap left, counted again every substep). Friction does act: without it the slip
  // would not fall below 1 m/s (the normal turns with the slide and only adds to it).
  const float gs_stiff = slip_speed(1000, kContactGaussSeidel), gs_soft = slip_speed(2, kContactGaussSeidel);
  report("gauss_seidel: relative slip speed after 0.25 s, stiff contacts", gs_stiff);
  report("gauss_seidel: relative slip speed after 0.25 s, soft contacts", gs_soft);
  const float coulomb = 1.0f - 1.0f * 0.01f * 48.0f;
  for (float slip : {gs_stiff, gs_soft}) {
    CHECK(slip > coulomb);
    CHECK(slip < 0.99f);
  }
}

TEST_CASE("final collision test keeps a 100 m/s grain out of a thin box", "[grains][colliders]") {
  // A grain moving 100 m/s crosses 100 / 240 = 0.42 m per substep, 40x the box's thickness:
  // the contact plane found from the predicted position lies behind the box, so only the swept
  // final collision test can stop it. With it the grain ends in front of the box (centre at
  // least r before the front face, up to the trace tolerance); without it, it passes.
  // At 50 m/s (0.21 m per substep) the substep that crosses ends with the centre at x = 0.042,
  // within r of the back face, so the iterations push the grain out of the back: the final
  // test has to see that it came through rather than push it out where it ended.
  for (float speed : {100.0f, 50.0f})
    for (bool final_test : {true, false}) {
      Scene sc;
      sc.s = settings(24, 10, 10);
      sc.s.final_collision_test = final_test;
      sc.gravity = {0, 0, 0};
      sc.add_collider(box({0, 0, 0}, {0.01f, 2, 2}));
      sc.add({-1, 0.1f, 0}, 0.05f, 1, {speed, 0, 0});
      sc.run(0.1f);
      float x = sc.pos(0).x;
      report(final_test ? "thin box, final test on: x" : "thin box, final test off: x", x);
      if (final_test) {
        CHECK(x <= -0.005f - 0.05f + 1e-4f);
        CHECK(sc.vel(0).x <= 1e-3f);
      } else {
        CHECK(x > 0.005f);
      }
    }
}

TEST_CASE("a fixed grain (mass 0) inside a collider stays where it is", "[grains][colliders]") {
  // Mass 0 means nothing moves the grain (a rough bed of fixed grains, a pinned anchor): a
  // collider that passes through it must not push it out, on either contact solver, whether
  // the final collision test is on or off. Half a radius inside a box's face, exactly where it
  // was after 0.25 s.
  for (int solver : {kContactJacobi, kContactGaussSeidel})
    for (bool final_test : {true, false}) {
      Scene sc;
      sc.s = settings(24, 4, 10);
      sc.s.contact_solver = solver;
      sc.s.final_collision_test = final_test;
      sc.add_collider(box({0, 0, 0}, {0.2f, 0.2f, 0.2f}));
      const Vec3 at{0.1f - 0.005f, 0.05f, 0};
      sc.add(at, 0.01f, 0.0f);
      sc.run(0.25f);
      INFO("solver " << solver << ", final test " << final_test << ": moved "
                     << length(sc.pos(0) - at));
      CHECK(sc.pos(0).x == at.x);
      CHECK(sc.pos(0).y == at.y);
      CHECK(sc.pos(0).z == at.z);
    }
}

TEST_CASE("the final collision test applies collider friction to a grain it stops",
          "[grains][colliders][friction]") {
  // The grain of the test above, now oblique: 100 m/s into the thin box's face and 173.2 m/s
  // along it (30 degrees to the face). It crosses the box within one substep and ends 0.2 m
  // behind it, so the iterations never see the contact and the swept final pass is the only
  // thing that can apply its friction. At velocity level the law of kernels/collider.h bounds
  // the tangential change by mu times the normal speed removed (100): mu = 0 keeps 173.2;
  // mu = 1 is kinetic (173.2 > static_threshold 1 x 100) and removes scale_kinetic 0.5 x 100,
  // leaving 123.2; mu = 2 sticks (173.2 < 2 x 100), leaving 0. Afterwards the grain moves
  // along the face at distance r (no overlap, so no friction) without gravity, so its velocity
  // stays as the hit left it. The error is float rounding of quantities near 200 m/s
  // (~1e-5 m/s per operation); 1e-3 m/s is well above it.
  const float vn = 100, vt = 173.205f;
  for (float mu : {0.0f, 1.0f, 2.0f}) {
    Scene sc;
    sc.s = settings(24, 10, 10);
    sc.s.friction_with_colliders = mu;
    sc.gravity = {0, 0, 0};
    sc.add_collider(box({0, 0, 0}, {0.01f, 2, 2}));
    sc.add({-1, 0.1f, -1.6f}, 0.05f, 1, {vn, 0, vt});
    sc.run(0.03f);
    const float expected = mu == 0 ? vt : (vt < mu * vn ? 0.0f : vt - 0.5f * mu * vn);
    const std::string what = "oblique hit on a thin box, mu " + std::to_string(mu) + ": v_t after";
    report(what.c_str(), sc.vel(0).z);
    CHECK(sc.pos(0).x <= -0.005f - 0.05f + 1e-4f);
    CHECK(std::fabs(sc.vel(0).x) < 1e-3f);
    CHECK(std::fabs(sc.vel(0).z - expected) < 1e-3f);
  }
}

namespace {

// side^3 grains of mixed sizes (512 by default) in a jittered lattice settle on the ground for
// 40 substeps with `setup` applied to the settings, on 1 thread and on each of `others`: the
// positions must match bit for bit.
void check_threads(void (*setup)(GrainsSettings&), int side = 8, std::vector<int> others = {2}) {
  auto run = [&](int threads) {
    Scene sc;
    sc.s = settings(24, 2, 20);
    sc.s.threads = threads;
    setup(sc.s);
    sc.add_collider(ground());
    test::Sequence seq;
    auto rnd = [&] { return seq.next(); };
    for (int a = 0; a < side; ++a)
      for (int b = 0; b < side; ++b)
        for (int c = 0; c < side; ++c)
          sc.add({0.09f * a + 0.01f * rnd(), 0.06f + 0.09f * b + 0.01f * rnd(),
                  0.09f * c + 0.01f * rnd()},
                 0.04f + 0.01f * rnd());
    sc.s.assume_uniform_radius = false;
    for (int k = 0; k < 40; ++k) sc.substep();
    return sc.P;
  };
  const std::vector<float> a = run(1);
  for (int threads : others) {
    INFO(threads << " threads");
    const std::vector<float> b = run(threads);
    REQUIRE(a.size() == b.size());
    CHECK(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
  }
}

}  // namespace

TEST_CASE("results are bit-identical for 1 and 2 threads", "[grains][determinism]") {
  // Gather-style Jacobi with static schedules: each grain's arithmetic is the same whatever
  // thread runs it, so the state must match bit for bit.
  check_threads([](GrainsSettings& s) {
    s.clumping_weight = 0.2f;
    s.accurate_friction = true;
    s.set_mass_shock(MassShock::Local);
  });
}

TEST_CASE("with the contacts one at a time, results are bit-identical for 1 and 2 threads",
          "[grains][determinism][gauss_seidel]") {
  // contact_solver gauss_seidel sweeps its contacts by blocks of grains in colours: 512 grains
  // are one block but make over kParallelContacts contacts, so the two runs take the threaded
  // and the serial sweep (concurrent blocks: the next test); clumping (the Jacobi pass after
  // each sweep) is threaded per grain, and the loads carried between substeps are keyed by ids
  check_threads([](GrainsSettings& s) {
    s.contact_solver = kContactGaussSeidel;
    s.clumping_weight = 0.2f;
  });
}

TEST_CASE("with the contacts one at a time, blocks swept at once give what one thread gives",
          "[grains][determinism][gauss_seidel]") {
  // 16^3 = 4,096 grains: four blocks of 1,024 (gauss_seidel.cpp, kBlockGrains) in colours, a
  // colour's blocks shared out among 2 and 3 threads; the warm start's sums and the sweeps'
  // largest move reduced across them
  check_threads([](GrainsSettings& s) { s.contact_solver = kContactGaussSeidel; }, 16, {2, 3});
}

TEST_CASE(
    "with the contacts one at a time, a block's contacts come in waves that move no grain twice",
    "[grains][gauss_seidel]") {
  // gauss_seidel.cpp (order_waves): with sweep_waves (a device whose work-items share a block)
  // each block's contacts are ordered in waves, no two contacts of a wave moving one grain, so
  // that a device may project a wave's contacts at once and get the sweep's bits. A jittered block
  // of 16 x 8 x 16 grains (two blocks of 1,024) settles on the ground for 24 substeps at 2 x 10.
  // Greedy colouring puts a contact in one of at most z_i + z_j - 1 waves (z a moving grain's
  // contacts in the block): the waves a block has are bounded by twice the most contacts any grain
  // has, less one, however many grains it holds.
  Scene sc;
  sc.s = settings(24, 2, 10);
  sc.s.contact_solver = kContactGaussSeidel;
  sc.s.sweep_waves = true;
  sc.add_collider(ground());
  sc.add_jittered_block(16, 8, 16, 0.01f);
  for (int k = 0; k < 24; ++k) sc.substep();
  const opencl::SequentialContacts on = sc.solver.contact_sweep();
  REQUIRE(on.blocks == 2);
  std::vector<int> last(sc.size(), -1);  // the wave a grain was last moved in
  size_t waves = 0;
  for (size_t b = 0; b < on.blocks; ++b) {
    INFO("block " << b);
    std::vector<int> in_block(sc.size(), 0);
    for (gr_uint k = on.block_start[b]; k < on.block_start[b + 1]; ++k) {
      const gr_seq_contact& q = on.contacts[k];
      CHECK(static_cast<size_t>(q.i) / 1024 == b);  // a contact belongs to its lower index's block
      if (q.moves & 1u) ++in_block[q.i];
      if (q.moves & 2u) ++in_block[q.j];
    }
    const int z = *std::max_element(in_block.begin(), in_block.end());
    const gr_uint w0 = on.block_wave[b], w1 = on.block_wave[b + 1];
    REQUIRE(w1 > w0);
    CHECK(on.wave_start[w0] == on.block_start[b]);
    CHECK(on.wave_start[w1] == on.block_start[b + 1]);
    INFO(on.block_start[b + 1] - on.block_start[b] << " contacts, at most " << z << " a grain, in "
                                                   << w1 - w0 << " waves");
    CHECK(on.block_start[b + 1] - on.block_start[b] > 4 * 1024u);  // a packing: the premise
    CHECK(static_cast<int>(w1 - w0) <= 2 * z - 1);
    for (gr_uint w = w0; w < w1; ++w) {
      CHECK(on.wave_start[w + 1] > on.wave_start[w]);  // no empty wave
      for (gr_uint k = on.wave_start[w]; k < on.wave_start[w + 1]; ++k) {
        const gr_seq_contact& q = on.contacts[k];
        for (int h = 0; h < 2; ++h) {
          if (!(q.moves & (1u << h))) continue;
          const int x = h ? q.j : q.i;
          CHECK(last[x] != static_cast<int>(w));  // moved once in a wave at most
          last[x] = static_cast<int>(w);
        }
      }
    }
    waves += w1 - w0;
  }
  CHECK(on.waves == waves);
}

TEST_CASE("with the contacts one at a time, a contact list kept across substeps gives what rebuilding it gives",
          "[grains][gauss_seidel]") {
  // While the neighbour rows are kept (no grain has moved a quarter of their skin) and no grain's
  // mass, repulsion or friction has changed, gauss_seidel keeps its contact list, with each
  // contact's load in place, instead of building it again and looking every load up by its
  // grains' ids. A state written and read back between substeps (a checkpoint) drops the list,
  // so the second run rebuilds it every substep: both must give the same bits. 512 grains in
  // layers half a radius apart fall onto the ground at 8 x 10: the fall moves the rows
  // (the list is rebuilt, its loads looked up), the rest keeps them.
  size_t kept = 0, rebuilt = 0;
  const std::vector<float> a = layered_drop(false, false, &kept).P;
  const std::vector<float> b = layered_drop(false, true, &rebuilt).P;
  INFO("substeps that kept the list: " << kept << " of 96 (round trip: " << rebuilt << ")");
  CHECK(kept >= 48);
  CHECK(kept < 96);
  CHECK(rebuilt == 0);
  REQUIRE(a.size() == b.size());
  CHECK(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

TEST_CASE("with the contacts one at a time, a packing that starts overlapping comes apart without velocity",
          "[grains][gauss_seidel]") {
  // The DEM column of bench/validation (4,854 grains of 1 cm between a back wall, side walls
  // 10 d apart and the floor), whose soft contacts overlap by 0.4% of d, at the first frame's
  // 256 substeps of 1/24 s. Pre-stabilization must remove that overlap from the start positions
  // without turning it into velocity. What it may leave is its tolerance, a move of
  // kStabilizeTolerance r a pass, and a leftover overlap o becomes a speed o / dt in the
  // passes: with gravity's g dt no grain may leave the first substep faster than
  // 0.002 r / dt + g dt (0.063 m/s). Measured: 1,332 passes, the fastest grain 0.024 m/s;
  // capped at 64 passes, as a substep with carried loads is, the last pass still moved a grain
  // 0.038 r and the fastest left at 0.46 m/s.
  ParticleStore packing = read_ply(test::source_dir() + "/bench/validation/data/dem_column.ply");
  REQUIRE(packing.size() == 4854);
  Scene sc;
  sc.s = settings(24, 256, 10);
  sc.s.contact_solver = kContactGaussSeidel;
  sc.s.friction_with_particles = sc.s.friction_with_colliders = 0.5f;
  sc.s.static_threshold = sc.s.scale_kinetic = 1.0f;
  sc.add_collider(ground());
  auto plane = [](const Vec3& at, const Vec3& turn) {
    ColliderState c = ground();
    c.pose = Pose::from_trs(at, turn, 1.0f);
    c.prev_pose = c.pose;
    return c;
  };
  sc.add_collider(plane({0, 0, 0}, {0, 0, -90}));    // the back wall, normal +x
  sc.add_collider(plane({0, 0, 0}, {90, 0, 0}));     // normal +z
  sc.add_collider(plane({0, 0, 0.1f}, {-90, 0, 0}));  // normal -z
  const float* P = packing.v3("P");
  const float* pscale = packing.f("pscale");
  for (size_t i = 0; i < packing.size(); ++i) sc.add({P[3 * i], P[3 * i + 1], P[3 * i + 2]}, pscale[i]);
  sc.substep();
  float fastest = 0;
  for (size_t i = 0; i < sc.size(); ++i) fastest = std::max(fastest, length(sc.vel(i)));
  const float r = pscale[0];  // every grain of the packing: 0.005 m
  const float bound = 0.002f * r / sc.s.dt + kG * sc.s.dt;
  report("DEM packing, first substep: fastest grain (m/s)", fastest);
  CHECK(fastest < bound);
}

TEST_CASE("with the contacts one at a time, a box settled at one pass a substep reports the velocity it moves at",
          "[grains][gauss_seidel]") {
  // 2,000 grains of 1 cm, 20 layers in a box 10 grains wide, settled for 1.5 s at 40 substeps
  // of one pass a frame. One pass does not stop a substep's sinking through 20 layers; the
  // overlap it leaves is removed by the next substep's pre-stabilization, which must also take
  // the velocity that made it, or the box keeps a velocity into its contacts that no motion shows
  // (and its reported kinetic energy never falls). Over the next frame the mean vertical velocity
  // the grains report must be what their motion shows, within one substep's gravity g dt
  // (0.010 m/s): a velocity is g dt off after any substep whose contacts have not yet stopped
  // it, and no more once the substeps before have taken theirs. Measured: -0.0099 m/s reported
  // against a motion of -0.0004 m/s; when pre-stabilization kept that velocity, -0.051 m/s
  // against -0.0023 m/s.
  Scene sc;
  sc.s = settings(24, 40, 1);
  sc.s.contact_solver = kContactGaussSeidel;
  sc.s.friction_with_particles = sc.s.friction_with_colliders = 1.0f;
  auto plane = [](const Vec3& at, const Vec3& turn) {
    ColliderState c = ground();
    c.pose = Pose::from_trs(at, turn, 1.0f);
    c.prev_pose = c.pose;
    return c;
  };
  const float r = 0.01f, half = 0.103f;
  sc.add_collider(ground());
  sc.add_collider(plane({-half, 0, 0}, {0, 0, -90}));  // normal +x
  sc.add_collider(plane({half, 0, 0}, {0, 0, 90}));    // normal -x
  sc.add_collider(plane({0, 0, -half}, {90, 0, 0}));   // normal +z
  sc.add_collider(plane({0, 0, half}, {-90, 0, 0}));   // normal -z
  test::Sequence seq;
  for (int b = 0; b < 20; ++b)
    for (int a = 0; a < 10; ++a)
      for (int c = 0; c < 10; ++c)
        sc.add({-0.0918f + 0.0204f * a + 0.001f * seq.next(), r + 0.0205f * b,
                -0.0918f + 0.0204f * c + 0.001f * seq.next()},
               r);
  sc.run(1.5f);
  const std::vector<float> before = sc.P;
  const float frame = 1.0f / 24.0f;
  sc.run(frame);
  double reported = 0, moved = 0;
  for (size_t i = 0; i < sc.size(); ++i) {
    reported += sc.v[3 * i + 1];
    moved += (sc.P[3 * i + 1] - before[3 * i + 1]) / frame;
  }
  reported /= static_cast<double>(sc.size());
  moved /= static_cast<double>(sc.size());
  report("box at 40 x 1: mean reported vertical velocity (m/s)", reported);
  report("box at 40 x 1: mean vertical velocity of the motion (m/s)", moved);
  CHECK(std::fabs(reported - moved) < kG * sc.s.dt);
}

TEST_CASE("mass-shock scaling lowers a tall stack's residual penetration", "[grains][massshock]") {
  // With mass-shock, each pair's correction moves the upper (lighter) grain more, so the
  // ground's push travels up a stack in fewer iterations: for the same iterations the settled
  // stack keeps less overlap. 100 grains, 60 iterations (under the 2x stacking-height rule).
  auto residual = [](MassShock mode, float power) {
    GrainsSettings s = settings(24, 4, 60);
    s.set_mass_shock(mode);
    s.shock_scaling_power = power;
    s.particle_separation = 0.1f;
    Scene sc = column(100, 0.05f, s);
    sc.run(2.0f);
    return sc.stats.max_penetration;
  };
  float off = residual(MassShock::Off, 0);
  float global = residual(MassShock::Global, 3);
  float local = residual(MassShock::Local, 3);
  report("100-stack max penetration, mass-shock off", off);
  report("100-stack max penetration, global power 3", global);
  report("100-stack max penetration, local power 3", local);
  CHECK(global < 0.8f * off);
  CHECK(local < 0.8f * off);
}

TEST_CASE("global mass-shock writes shockmass", "[grains][massshock]") {
  // shockmass = mass * exp(-0.15 * power * h / separation), h = (P - origin) . axis
  GrainsSettings s = settings(24, 1, 5);
  s.set_mass_shock(MassShock::Global);
  s.shock_scaling_power = 2;
  s.particle_separation = 0.1f;
  s.shock_axis = {0, 2, 0};  // normalised by the solver
  s.shock_origin = {0, 0.5f, 0};
  Scene sc;
  sc.s = s;
  sc.gravity = {0, 0, 0};
  sc.add({0, 0.5f, 0}, 0.05f, 2.0f);
  sc.add({0, 1.5f, 0}, 0.05f, 2.0f);
  sc.add({0, 1e4f, 0}, 0.05f, 1.0f);  // far: exponent clamped at -80
  sc.substep();
  CHECK(sc.shockmass[0] == Approx(2.0f));
  CHECK(sc.shockmass[1] == Approx(2.0f * std::exp(-0.15 * 2 * 1.0 / 0.1)).epsilon(1e-5));
  CHECK(sc.shockmass[2] == Approx(std::exp(-80.0)).epsilon(1e-4));
  CHECK(std::isfinite(sc.shockmass[2]));
}

namespace {

// The largest overlap over all pairs, by brute force (independent of the solver's neighbour
// lists, which max_neighbors may truncate), as a fraction of r_i + r_j.
float max_overlap(const Scene& sc) {
  float m = 0;
  for (size_t i = 0; i < sc.size(); ++i)
    for (size_t j = i + 1; j < sc.size(); ++j) {
      float rs = sc.pscale[i] + sc.pscale[j];
      m = std::max(m, (rs - length(sc.pos(i) - sc.pos(j))) / rs);
    }
  return m;
}

// Two grains of radius 0.05 overlapping by `overlap` (m) along x, at rest, no gravity. Without
// pre-stabilization, which would remove an overlap the grains start with before the iterations
// see it: these tests measure what the iterations do with it.
Scene overlapping_pair(float overlap, const GrainsSettings& s) {
  Scene sc;
  sc.s = s;
  sc.s.pre_stabilization = false;
  sc.gravity = {0, 0, 0};
  sc.add({0, 0, 0}, 0.05f);
  sc.add({0.1f - overlap, 0, 0}, 0.05f);
  return sc;
}

}  // namespace

TEST_CASE("stiffness: the per-frame enforcement depends on substeps x iterations only",
          "[grains][stiffness]") {
  // Stiffness k gives a per-iteration fraction c = min(1, k / (substeps x iterations)). With
  // velocity_blend 1 the constraints inject no velocity and with no forces a frame is exactly
  // N = substeps x iterations relaxation steps: a pair's overlap after one frame is
  // o0 (1 - k/N)^N. So 1 x 20 and 2 x 10 give the same result (to rounding, 1e-6 relative), and
  // another product only a similar one ((1 - k/N)^N -> e^-k: the help page's "approximate"
  // stiffness): for k = 2, 0.9^20 = 0.122 vs 0.8^10 = 0.107.
  auto pair = [](int substeps, int iterations, float k) {
    GrainsSettings s = settings(24, substeps, iterations);
    s.internal_collisions_stiffness = k;
    s.velocity_blend = 1;
    Scene sc = overlapping_pair(0.02f, s);
    sc.run(1.0f / 24);
    return (0.1f - length(sc.pos(1) - sc.pos(0))) / 0.02f;
  };
  float r20 = pair(1, 20, 2), r2x10 = pair(2, 10, 2), r10 = pair(1, 10, 2);
  report("stiffness 2: overlap left, 1x20 (0.9^20 = 0.1216)", r20);
  report("stiffness 2: overlap left, 2x10", r2x10);
  report("stiffness 2: overlap left, 1x10 (0.8^10 = 0.1074)", r10);
  CHECK(r20 == Approx(std::pow(0.9, 20)).epsilon(1e-4));
  CHECK(r2x10 == Approx(r20).epsilon(1e-6));
  CHECK(r10 == Approx(std::pow(0.8, 10)).epsilon(1e-4));

  // fully enforced once k >= substeps x iterations: the same result as k = 1e9, bit for bit,
  // on a compressed cluster; a tenth of that stiffness leaves more overlap (at half, gauss_seidel
  // still clears the cluster within the frame). Without
  // pre-stabilization, whose passes (at most the iterations' count) would remove the starting
  // overlap before the iterations see it, as for the pair above.
  auto cluster = [](float k) {
    GrainsSettings s = settings(24, 2, 10);
    s.internal_collisions_stiffness = k;
    s.pre_stabilization = false;
    Scene sc;
    sc.s = s;
    sc.gravity = {0, 0, 0};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int c = 0; c < 3; ++c) sc.add({0.08f * a + 0.003f * b, 0.08f * b, 0.08f * c}, 0.05f);
    sc.run(1.0f / 24);
    return sc;
  };
  Scene full = cluster(20), inf = cluster(1e9f), weak = cluster(2);
  CHECK(std::memcmp(full.P.data(), inf.P.data(), full.P.size() * sizeof(float)) == 0);
  CHECK(max_overlap(weak) > max_overlap(full));
}

TEST_CASE("repulsion weight 0 turns particle collisions off", "[grains]") {
  // Help page: "A value of zero will disable particle collision."
  GrainsSettings s = settings(24, 1, 10);
  s.internal_collisions_weight = 0;
  Scene sc = overlapping_pair(0.05f, s);
  sc.substep();
  CHECK(sc.pos(1).x == Approx(0.05f));
  s.internal_collisions_weight = 1;
  Scene on = overlapping_pair(0.05f, s);
  on.substep();
  CHECK(on.pos(1).x - on.pos(0).x == Approx(0.1f).epsilon(1e-4));
}

TEST_CASE("clumping pulls nearby grains to contact and holds a hanging chain",
          "[grains][clumping]") {
  // Two grains 1.3 (r_i + r_j) apart, inside the query range 1.5: clumping closes the gap, the
  // closing speed is removed by the contact on arrival (PBD is inelastic), so they end touching:
  // |dist - 0.1| < 1% (residual overlap of one substep's motion is << 1 mm).
  auto pair_gap = [](float weight, float query_scale) {
    GrainsSettings s = settings(24, 2, 20);
    s.clumping_weight = weight;
    s.neighbor_query_scale = query_scale;
    Scene sc;
    sc.s = s;
    sc.gravity = {0, 0, 0};
    sc.add({0, 0, 0}, 0.05f);
    sc.add({0.13f, 0, 0}, 0.05f);
    sc.run(1.0f);
    return length(sc.pos(1) - sc.pos(0));
  };
  float pulled = pair_gap(1, 1.5f);
  report("clumped pair distance (0.1 = contact)", pulled);
  CHECK(std::fabs(pulled - 0.1f) < 0.001f);
  CHECK(pair_gap(0, 1.5f) == Approx(0.13f));
  // neighbor_query_scale is the clumping range (help page): at 1.2 the pair is out of reach
  CHECK(pair_gap(1, 1.2f) == Approx(0.13f));

  // A chain of 5 grains hanging under an anchor grain (mass 1e6, its weight cancelled): with
  // clumping the chain stays attached (each link within the 1.5 (r_i + r_j) range, the bottom
  // less than a diameter below its start); without, it falls ~ g t^2 / 2 = 4.9 m in 1 s.
  auto hang = [](float weight) {
    GrainsSettings s = settings(24, 2, 20);
    s.clumping_weight = weight;
    Scene sc;
    sc.s = s;
    sc.add({0, 0, 0}, 0.05f, 1e6f);
    for (int k = 1; k <= 5; ++k) sc.add({0, -0.1f * k, 0}, 0.05f);
    sc.extra_force.assign(sc.size(), Vec3{0, 0, 0});
    sc.extra_force[0] = Vec3{0, kG * 1e6f, 0};
    sc.run(1.0f);
    return sc;
  };
  Scene held = hang(1), fell = hang(0);
  float worst_link = 0;
  for (size_t k = 1; k < held.size(); ++k)
    worst_link = std::max(worst_link, length(held.pos(k) - held.pos(k - 1)));
  report("hanging chain: longest link (0.1 = contact, range 0.15)", worst_link);
  CHECK(worst_link < 0.15f);
  CHECK(held.pos(5).y > -0.5f - 0.1f);
  CHECK(fell.pos(5).y < -0.5f - 4.0f);
}

TEST_CASE("clumping pulls as a force at the finer substeps error control takes", "[grains][clumping]") {
  // Clumping pulls two grains that are apart toward contact by a fraction of their gap a
  // substep; a move is a speed move / dt.
  // At the solver's substeps (base_dt) that is POP Grains' clumping; at substeps 64 times finer
  // (error control refines the frame, keeping base_dt) the same fraction would close the gap
  // in a 64th of the time, at 64 times the speed (settle_10k with clumping at the defaults
  // reached 17 MJ of kinetic energy in two frames). Scaled by (dt / base_dt)^2 the pull is a
  // force: I iterations move each of two equal grains at most half the gap g times the weight
  // w a substep, so the pair's relative acceleration is at most I w g / base_dt^2 and, closing
  // from the gap g0, its approach speed at most sqrt(2 I w) g0 / base_dt (6.4 m/s here; a gap
  // closed in one fine substep would be 92 m/s). Two grains 1.3 (r_i + r_j) apart, no gravity.
  GrainsSettings s = settings(24, 2, 10);
  s.clumping_weight = 1;
  const float base_dt = s.dt, g0 = 0.13f - 0.1f;
  s.base_dt = base_dt;
  s.dt = base_dt / 64;
  Scene sc;
  sc.s = s;
  sc.gravity = {0, 0, 0};
  sc.add({0, 0, 0}, 0.05f);
  sc.add({0.13f, 0, 0}, 0.05f);
  float fastest = 0;
  for (int k = 0; k < 64 * 48; ++k) {
    sc.substep();
    fastest = std::max(fastest, length(sc.vel(1) - sc.vel(0)));
  }
  const float bound = std::sqrt(2.0f * s.constraint_iterations * s.clumping_weight) * g0 / base_dt;
  report("clumping at 64 x finer substeps: fastest approach (m/s)", fastest);
  report("  bound sqrt(2 I w) g0 / base_dt", bound);
  CHECK(fastest <= bound);
  // and it still clumps: the pair ends touching, as at the solver's own substeps
  CHECK(std::fabs(length(sc.pos(1) - sc.pos(0)) - 0.1f) < 0.001f);
}

TEST_CASE("max speed caps the reported velocity, not the substep's motion", "[grains]") {
  // Help page: max speed limits v but "does not actually control how far the particle will move
  // in a frame". A grain thrown down at 5 m/s: after one substep P matches the uncapped run
  // exactly and |v| = 1; later substeps start from the capped v and fall behind.
  auto thrown = [](float max_speed, int substeps) {
    Scene sc;
    sc.s = settings(24, 2, 5);
    sc.s.max_speed = max_speed;
    sc.add({0, 10, 0}, 0.05f, 1, {0, -5, 0});
    for (int k = 0; k < substeps; ++k) sc.substep();
    return sc;
  };
  Scene capped = thrown(1, 1), free = thrown(1e6f, 1);
  CHECK(capped.pos(0).y == free.pos(0).y);
  CHECK(length(capped.vel(0)) == Approx(1.0f));
  CHECK(length(free.vel(0)) > 5.0f);
  CHECK(thrown(1, 10).pos(0).y > thrown(1e6f, 10).pos(0).y + 0.1f);
}

TEST_CASE("max acceleration caps the velocity the constraints inject", "[grains]") {
  // Two grains overlapping by 4 cm are pushed apart 2 cm each in one substep: uncapped that is
  // 0.02 / dt = 0.96 m/s; capped, |v - v_pred| <= max_acceleration x dt = 10 / 48 m/s.
  GrainsSettings s = settings(48, 1, 10);
  Scene free = overlapping_pair(0.04f, s);
  free.substep();
  s.max_acceleration = 10;
  Scene capped = overlapping_pair(0.04f, s);
  capped.substep();
  CHECK(length(free.vel(1)) == Approx(0.02f * 48).epsilon(1e-3));
  CHECK(length(capped.vel(1)) == Approx(10.0f / 48).epsilon(1e-4));
}

TEST_CASE("drift threshold keeps slow grains where they were", "[grains]") {
  // A grain gliding at 5 cm/s on frictionless ground: under a 0.1 m/s threshold it stays at
  // its previous position with v = 0 (help page); with no threshold it moves 5 cm in 1 s.
  for (float drift : {0.0f, 0.1f}) {
    Scene sc;
    sc.s = settings(24, 2, 5);
    sc.s.drift_threshold = drift;
    sc.s.friction_with_colliders = 0;
    sc.add_collider(ground());
    sc.add({0, 0.05f, 0}, 0.05f, 1, {0.05f, 0, 0});
    sc.run(1.0f);
    if (drift > 0) {
      CHECK(sc.pos(0).x == 0.0f);
      CHECK(length(sc.vel(0)) == 0.0f);
    } else {
      CHECK(sc.pos(0).x == Approx(0.05f).epsilon(1e-3));
    }
  }
}

TEST_CASE("velocity blend mixes the motion-derived and the predicted velocity", "[grains]") {
  // v = (1 - b) (p - P)/dt + b v_pred; for a pushed-apart pair at rest v_pred = 0, so v scales
  // with (1 - b) exactly (rounding only), while the positions are the same.
  GrainsSettings s = settings(48, 1, 10);
  float speed[3];
  float x[3];
  for (int k = 0; k < 3; ++k) {
    s.velocity_blend = 0.5f * k;
    Scene sc = overlapping_pair(0.04f, s);
    sc.substep();
    speed[k] = sc.vel(1).x;
    x[k] = sc.pos(1).x;
  }
  CHECK(speed[0] > 0.5f);
  CHECK(speed[1] == Approx(0.5f * speed[0]).epsilon(1e-5));
  CHECK(speed[2] == 0.0f);
  CHECK(x[0] == x[1]);
  CHECK(x[1] == x[2]);
}

TEST_CASE("over-relaxation speeds up the Jacobi iterations on a stack; one at a time it still holds it",
          "[grains]") {
  // Jacobi with averaging under-corrects (help page); omega = 1.5 scales each averaged step up,
  // so a 20-grain column with only 10 iterations sags less (the sag estimate 2 delta N^2 / I
  // shrinks roughly by omega).
  auto sag = [](ContactSolver solver, float omega) {
    GrainsSettings s = settings(24, 2, 10);
    s.contact_solver = solver;
    s.over_relaxation = omega;
    Scene sc = column(20, 0.05f, s);
    sc.run(2.0f);
    return 1.95f - sc.max_y();
  };
  const float plain = sag(kContactJacobi, 1), boosted = sag(kContactJacobi, 1.5f);
  report("20-column sag, jacobi, omega 1", plain);
  report("20-column sag, jacobi, omega 1.5", boosted);
  CHECK(boosted < 0.8f * plain);
  // gauss_seidel takes omega as successive over-relaxation of each contact's normal step. Its
  // carried loads, with the velocity that made an overlap taken by the next pre-stabilization,
  // already hold the column at omega = 1 (measured 0.0002 m of 1.95 m; 0.051 m before that
  // velocity was taken, when omega 1.5 helped: 0.017 m); over-relaxed, the steps overshoot and
  // the column ends 0.009 m low. Both must stand within 1% of the column's height, and omega
  // must change the result.
  const float seq_plain = sag(kContactGaussSeidel, 1), seq_boosted = sag(kContactGaussSeidel, 1.5f);
  report("20-column sag, gauss_seidel, omega 1", seq_plain);
  report("20-column sag, gauss_seidel, omega 1.5", seq_boosted);
  CHECK(std::fabs(seq_plain) < 0.01f * 1.95f);
  CHECK(std::fabs(seq_boosted) < 0.01f * 1.95f);
  CHECK(seq_boosted != seq_plain);
}

static void check_chebyshev(bool opencl) {
  // An 8 x 10 x 10 block of grains (r = 5 cm, jittered) between four walls collapses into a
  // pile, 2 substeps x 20 iterations for 2 s. For a linear iteration whose slowest modes decay
  // like rho per iteration, Chebyshev extrapolation over the 15 iterations after the delay
  // shrinks them by 1 / T_15(1 / rho) (1/65 for rho = 0.95) instead of rho^15 (0.46). Contacts
  // opening and closing keep the gain far smaller, so the test asks only for half the plain
  // mean penetration. Extrapolation must not create energy: the pile starts at rest and can
  // only lose energy, so kinetic plus potential energy at the end must stay below the start's.
  const float r = 0.05f;
  struct Result {
    float pen, energy_start, energy_end;
  };
  auto energy = [](const Scene& sc) {
    double e = 0;
    for (size_t i = 0; i < sc.size(); ++i)
      e += sc.mass[i] * (0.5 * dot(sc.vel(i), sc.vel(i)) + kG * sc.pos(i).y);
    return static_cast<float>(e);
  };
  auto pile = [&](float rho) {
    Scene sc;
    sc.s = settings(24, 2, 20);
    sc.s.chebyshev_rho = rho;
    sc.s.use_opencl = opencl;
    sc.s.contact_solver = kContactJacobi;  // Chebyshev steps Jacobi iterations
    sc.add_collider(ground());
    // four walls around the block: planes through the block's faces, normals inward
    auto wall = [](Vec3 at, Vec3 degrees) {
      ColliderState c = ground();
      c.pose = Pose::from_trs(at, degrees, 1.0f);
      c.prev_pose = c.pose;
      return c;
    };
    sc.add_collider(wall({-r, 0, 0}, {0, 0, -90}));
    sc.add_collider(wall({19 * r, 0, 0}, {0, 0, 90}));
    sc.add_collider(wall({0, 0, -r}, {90, 0, 0}));
    sc.add_collider(wall({0, 0, 19 * r}, {-90, 0, 0}));
    sc.add_jittered_block(10, 8, 10, r);
    const float e0 = energy(sc);
    sc.run(2.0f);
    return Result{sc.stats.mean_penetration, e0, energy(sc)};
  };
  const Result plain = pile(0), fast = pile(0.95f);
  report("walled 8-layer block at 2 x 20, mean penetration, plain", plain.pen);
  report("walled 8-layer block at 2 x 20, mean penetration, rho 0.95", fast.pen);
  report("walled 8-layer block, energy end / start, plain", plain.energy_end / plain.energy_start);
  report("walled 8-layer block, energy end / start, rho 0.95", fast.energy_end / fast.energy_start);
  CHECK(fast.pen < 0.5f * plain.pen);
  CHECK(fast.energy_end < fast.energy_start);
}

TEST_CASE("Chebyshev acceleration (not in POP Grains) settles a pile with less overlap",
          "[grains]") {
  check_chebyshev(false);
}

TEST_CASE("use_opencl: Chebyshev acceleration settles a pile with less overlap on the OpenCL device",
          "[grains][opencl]") {
  // the iterations on PoCL's CPU device, the Chebyshev step on the host: the same bounds
  check_chebyshev(true);
}

TEST_CASE("constraint averaging moves an asymmetric clump's centre and disabling it does not",
          "[grains]") {
  // Help page: averaging "does not preserve momentum", so clumps "accelerate under their own
  // force"; disabling it avoids these ghost forces. An L of three overlapping grains in zero
  // gravity: the corner grain averages two contacts, the ends one, so with averaging the pair
  // corrections no longer cancel and the centre moves (~1 mm); without averaging (weights 0.5,
  // as the help page asks) equal and opposite corrections leave it still to rounding (1e-6 m).
  auto drift = [](bool disable, ContactSolver solver = kContactJacobi) {
    GrainsSettings s = settings(24, 2, 10);
    s.contact_solver = solver;
    s.disable_constraint_averaging = disable;
    s.pre_stabilization = false;  // the iterations, not the pre-stabilization, meet the overlap
    if (disable) s.internal_collisions_weight = 0.5f;
    Scene sc;
    sc.s = s;
    sc.gravity = {0, 0, 0};
    sc.add({0, 0, 0}, 0.05f);
    sc.add({0.09f, 0, 0}, 0.05f);
    sc.add({0, 0.09f, 0}, 0.05f);
    Vec3 c0 = sc.centroid();
    sc.run(0.25f);
    return length(sc.centroid() - c0);
  };
  float on = drift(false), off = drift(true);
  report("L-clump centroid drift, averaging", on);
  report("L-clump centroid drift, averaging disabled", off);
  CHECK(on > 1e-3f);
  CHECK(off < 1e-6f);
  // gauss_seidel (the default) moves both grains of a contact by equal and opposite shares, one
  // contact at a time: no ghost force, averaging or not
  const float gs = drift(false, kContactGaussSeidel);
  report("L-clump centroid drift, gauss_seidel", gs);
  CHECK(gs < 1e-6f);
}

TEST_CASE("max neighbors: a tight cap misses contacts", "[grains]") {
  // A compressed 4x4x4 cluster has up to 6 overlapping neighbours per grain; capped at 2 most
  // are never seen and stay overlapping, measured by brute force.
  auto overlap = [](int cap) {
    GrainsSettings s = settings(24, 1, 20);
    s.max_neighbors = cap;
    Scene sc;
    sc.s = s;
    sc.gravity = {0, 0, 0};
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int c = 0; c < 4; ++c) sc.add({0.085f * a, 0.085f * b, 0.085f * c}, 0.05f);
    sc.substep();
    return max_overlap(sc);
  };
  float full = overlap(32), capped = overlap(2);
  report("cluster max overlap, max_neighbors 32", full);
  report("cluster max overlap, max_neighbors 2", capped);
  CHECK(capped > 2 * full);
}

static void check_update_neighbors(bool opencl) {
  // Query scale 1 gives no margin: B is pushed by A into C, which was not a candidate at
  // prediction. Without updates B and C end overlapping; rebuilt every iteration, the contact is
  // found and resolved to well under the initial 40% overlap.
  auto run = [opencl](bool update) {
    GrainsSettings s = settings(24, 1, 20);
    s.neighbor_query_scale = 1.0f;
    s.update_neighbors_during_iterations = update;
    s.use_opencl = opencl;
    s.contact_solver = kContactJacobi;  // gauss_seidel finds its contacts once a substep
    Scene sc;
    sc.s = s;
    sc.gravity = {0, 0, 0};
    sc.add({0, 0, 0}, 0.05f);
    sc.add({0.06f, 0, 0}, 0.05f);
    sc.add({0.165f, 0, 0}, 0.05f);
    sc.substep();
    return sc;
  };
  Scene stale = run(false), fresh = run(true);
  float bc_stale = 0.1f - length(stale.pos(2) - stale.pos(1));
  float bc_fresh = 0.1f - length(fresh.pos(2) - fresh.pos(1));
  report("B-C overlap, neighbours once", bc_stale);
  report("B-C overlap, neighbours every iteration", bc_fresh);
  CHECK(bc_stale > 0.005f);
  CHECK(bc_fresh < 0.5f * bc_stale);
}

TEST_CASE("update neighbours during iterations finds contacts the iterations create",
          "[grains]") {
  check_update_neighbors(false);
}

TEST_CASE("use_opencl: update neighbours during iterations finds contacts the iterations create on the OpenCL device",
          "[grains][opencl]") {
  // each iteration on PoCL's CPU device after the host rebuilt the rows: the same bounds
  check_update_neighbors(true);
}

static void check_update_collisions(bool opencl) {
  // Grain A (r = 5 cm) sits 10 cm above the ground, beyond the plane query range of
  // 1.5 r = 7.5 cm, and a 3x heavier grain B overlaps it from above by 9 cm. The contact
  // pushes A down by w_A / (w_A + w_B) x 9 cm = 6.75 cm, 1.75 cm into the ground. With planes
  // found once per substep A never learns of the ground; re-found every iteration, the ground
  // holds it and B is pushed up instead. No gravity, no friction, no final collision test: only the
  // iterations act.
  auto ground_penetration = [opencl](bool update) {
    GrainsSettings s = settings(24, 1, 10);
    s.update_collisions_during_iterations = update;
    s.use_opencl = opencl;
    s.contact_solver = kContactJacobi;  // gauss_seidel finds its planes once a substep
    s.final_collision_test = false;
    s.friction_with_colliders = 0;
    s.friction_with_particles = 0;
    Scene sc;
    sc.s = s;
    sc.gravity = {0, 0, 0};
    sc.add_collider(ground());
    sc.add({0, 0.10f, 0}, 0.05f, 1.0f);
    sc.add({0, 0.11f, 0}, 0.05f, 3.0f);
    sc.substep();
    return 0.05f - sc.pos(0).y;
  };
  float once = ground_penetration(false), every = ground_penetration(true);
  report("ground penetration, planes once", once);
  report("ground penetration, planes every iteration", every);
  // once: 3/4 of the 9 cm overlap, minus the 5 cm of clearance
  CHECK(once == Approx(0.75f * 0.09f - 0.05f).margin(1e-3));
  CHECK(every < 0.5f * once);
}

TEST_CASE("update collisions during iterations finds a collider the iterations push into",
          "[grains][colliders]") {
  check_update_collisions(false);
}

TEST_CASE("use_opencl: update collisions during iterations finds a collider the iterations push into on the OpenCL device",
          "[grains][colliders][opencl]") {
  // each iteration on PoCL's CPU device after the host re-found the planes: the same bounds
  check_update_collisions(true);
}

TEST_CASE("a grain in a corner feels both surfaces", "[grains][colliders]") {
  // A grain wedged into a corner penetrates a wall by 3 cm and the ground by 2 cm. Both planes
  // are kept (nearest first), so ten averaged iterations leave each penetration at about
  // 0.5^10 of its start, under 0.1 mm. No friction, no final collision test.
  GrainsSettings s = settings(24, 1, 10);
  s.final_collision_test = false;
  s.friction_with_colliders = 0;
  Scene sc;
  sc.s = s;
  sc.gravity = {0, 0, 0};
  sc.add_collider(ground());
  sc.add_collider(box({0.5f, 0, 0}, {1, 2, 2}));  // wall face at x = 0
  sc.add({-0.02f, 0.03f, 0}, 0.05f);
  sc.substep();
  CHECK(0.05f - sc.pos(0).y < 1e-4f);
  CHECK(sc.pos(0).x + 0.05f < 1e-4f);
}

TEST_CASE("a moving box pushes grains and carries one on top", "[grains][colliders]") {
  // Box 1 m wide moving +x at 0.5 m/s for 1 s.
  auto moving_box = [](float y) {
    ColliderState c = box({0, y, 0}, {1, 1, 1});
    auto motion = [y](float t) {
      Pose p;
      p.t = {0.5f * t, y, 0};
      return p;
    };
    return std::make_pair(c, motion);
  };
  // pushed: a grain on frictionless ground ahead of the box ends ahead of its face (x >= face + r,
  // within rounding) having moved with it
  {
    Scene sc;
    sc.s = settings(24, 2, 10);
    sc.s.friction_with_colliders = 0;
    sc.add_collider(ground());
    auto [c, m] = moving_box(0.5f);
    sc.add_collider(c, m);
    sc.add({0.6f, 0.05f, 0}, 0.05f);
    sc.run(1.0f);
    float face = 0.5f + 0.5f;
    report("pushed grain x (box face at 1.0)", sc.pos(0).x);
    CHECK(sc.pos(0).x >= face + 0.05f - 1e-4f);
    CHECK(sc.pos(0).y == Approx(0.05f).margin(1e-3));
  }
  // carried: a grain resting on top reaches the box's speed by kinetic friction (a = mu_k g =
  // 4.9 m/s^2, 0.1 s) and then sticks: it lags the box by ~ v^2 / (2 a) = 2.5 cm at most.
  // Without collider friction it stays behind.
  for (float fc : {1.0f, 0.0f}) {
    Scene sc;
    sc.s = settings(24, 2, 10);
    sc.s.friction_with_colliders = fc;
    auto [c, m] = moving_box(0);
    sc.add_collider(c, m);
    sc.add({0, 0.55f, 0}, 0.05f);
    sc.run(1.0f);
    report(fc > 0 ? "carried grain x (box moved 0.5)" : "frictionless grain x", sc.pos(0).x);
    if (fc > 0) {
      CHECK(sc.pos(0).x == Approx(0.5f).margin(0.03f));
      CHECK(sc.vel(0).x == Approx(0.5f).margin(0.01f));
      CHECK(sc.pos(0).y == Approx(0.55f).margin(1e-3f));
    } else {
      CHECK(std::fabs(sc.pos(0).x) < 1e-4f);
    }
  }
}

TEST_CASE("a 1000:1 heavy grain rests on a bed of small grains", "[grains][massshock]") {
  // A grain of 10x the radius (1000x the mass) on three layers of small grains (r = 0.05) on the
  // ground. A pair shares corrections by inverse mass, so the small grain takes 99.9% of each and
  // the big one's weight needs overlaps ~1000x larger than a small grain's to be carried: it
  // sinks. Global mass-shock (power 5, separation 0.1) makes the big grain, 4.5 separations
  // higher than the bed's centre line, lighter by exp(-0.15 x 5 x 4.5) ~ 1/30, which keeps it on
  // top: its lowest point must stay above the bed's middle layer (y > 0.2 m; bed top 0.3 m).
  auto bed = [](MassShock mode) {
    GrainsSettings s = settings(24, 2, 40);
    s.assume_uniform_radius = false;
    s.set_mass_shock(mode);
    s.shock_scaling_power = 5;
    s.particle_separation = 0.1f;
    s.accurate_friction = true;
    Scene sc;
    sc.s = s;
    sc.add_collider(ground());
    for (int l = 0; l < 3; ++l)
      for (int a = -7; a <= 7; ++a)
        for (int c = -7; c <= 7; ++c) sc.add({0.1f * a, 0.05f + 0.1f * l, 0.1f * c}, 0.05f);
    sc.add({0, 0.3f + 0.5f, 0}, 0.5f, 1000.0f);
    sc.run(1.5f);
    return sc.pos(sc.size() - 1).y - 0.5f;
  };
  float bottom = bed(MassShock::Global);
  report("big grain lowest point, global mass-shock (bed top 0.3)", bottom);
  report("big grain lowest point, no mass-shock", bed(MassShock::Off));
  CHECK(bottom > 0.2f);
}

TEST_CASE("the friction point attribute scales friction", "[grains][friction]") {
  // friction_with_colliders x `friction`: a grain at 30 degrees (under atan 1 = 45) sticks with
  // the attribute 1 and with it 0 slides as on a frictionless plane, g sin t^2 / 2 (1 + dt / t)
  // = 0.62 m in 0.5 s (the factor is semi-implicit Euler's, see the frictionless test); 0.5%
  // covers float rounding over 48 substeps.
  const float deg = 30, th = deg * static_cast<float>(M_PI) / 180.0f, r = 0.05f;
  for (float attr : {1.0f, 0.0f}) {
    Scene sc;
    sc.s = settings(24, 2, 10);
    sc.add_collider(incline(deg));
    Vec3 n{-std::sin(th), std::cos(th), 0};
    sc.add(n * r, r);
    sc.friction = {attr};
    sc.run(0.5f);
    float moved = length(sc.pos(0) - n * r);
    if (attr > 0)
      CHECK(moved < 1e-6f);
    else
      CHECK(moved == Approx(0.5f * kG * 0.5f * 0.25f * (1 + sc.s.dt / 0.5f)).epsilon(0.005));
  }
}
