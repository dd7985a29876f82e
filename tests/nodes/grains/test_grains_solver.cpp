// Physics tests of the grains PBD solver (DESIGN §4, the POP Grains help page). Each test states
// the law or closed form it checks and derives its tolerance from the physics of the scheme.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cstring>

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
  // ~ 7%: the column must sag by more than 1%.
  const float r = 0.05f;
  const float expected = 49 * 2 * r + r;
  Scene good = column(50, r, settings(24, 5, 100));
  good.run(3.0f);
  float err = std::fabs(good.max_y() - expected) / expected;
  report("column 50, 4 substeps x 100 iterations: relative height error", err);
  CHECK(err < 0.01f);

  Scene poor = column(50, r, settings(24, 5, 10));
  poor.run(3.0f);
  float sag = (expected - poor.max_y()) / expected;
  report("column 50, 4 substeps x 10 iterations: relative sag", sag);
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

}  // namespace

TEST_CASE("grains stick on an incline below a threshold angle that rises with friction",
          "[grains][friction]") {
  // Coulomb law of Macklin's friction: per substep a resting grain slips g sin dt^2 along the
  // plane and sinks g cos dt^2 into it, and the friction scale multiplies that bound, so it
  // sticks while tan(theta) < mu = static_threshold x friction_with_colliders. With
  // static_threshold 1, friction 0.25 / 0.5 / 1 gives atan(mu) = 14.0 / 26.6 / 45 degrees.
  // A two-layer block with accurate friction (the mode that stacks grains, help page) either
  // sticks (it creeps < 1 cm/s from the Jacobi averaging) or slides: 5 degrees past the
  // threshold it accelerates at g (sin - mu_k cos) > 0.8 m/s^2, > 40 cm in 1 s. Scanning
  // 7.5, 12.5, ... degrees, the first sliding angle lies in [atan(mu), atan(mu) + 5].
  auto threshold = [](float fc) {
    GrainsSettings s = settings(24, 2, 20);
    s.accurate_friction = true;
    s.friction_with_colliders = fc;
    for (float deg = 7.5f; deg <= 60; deg += 5)
      if (block_slide(deg, s) > 0.01f) return deg;
    return 90.0f;
  };
  float t1 = threshold(0.25f), t2 = threshold(0.5f), t3 = threshold(1.0f);
  report("incline sliding threshold (deg), friction 0.25 (atan 14.0)", t1);
  report("incline sliding threshold (deg), friction 0.5 (atan 26.6)", t2);
  report("incline sliding threshold (deg), friction 1 (atan 45)", t3);
  CHECK(t1 < t2);
  CHECK(t2 < t3);
  CHECK(t1 >= 14.04f);
  CHECK(t1 <= 14.04f + 5);
  CHECK(t2 >= 26.57f);
  CHECK(t2 <= 26.57f + 5);
  CHECK(t3 >= 45.0f);
  CHECK(t3 <= 45.0f + 5);
}

TEST_CASE("final collision test keeps a 100 m/s grain out of a thin box", "[grains][colliders]") {
  // A grain moving 100 m/s crosses 100 / 240 = 0.42 m per substep, 40x the box's thickness:
  // the contact plane found from the predicted position lies behind the box, so only the swept
  // final collision test can stop it. With it the grain ends in front of the box (centre at
  // least r before the front face, up to the trace tolerance); without it, it passes.
  for (bool final_test : {true, false}) {
    Scene sc;
    sc.s = settings(24, 10, 10);
    sc.s.final_collision_test = final_test;
    sc.gravity = {0, 0, 0};
    sc.add_collider(box({0, 0, 0}, {0.01f, 2, 2}));
    sc.add({-1, 0.1f, 0}, 0.05f, 1, {100, 0, 0});
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

TEST_CASE("results are bit-identical for 1 and 2 threads", "[grains][determinism]") {
  // Gather-style Jacobi with static schedules: each grain's arithmetic is the same whatever
  // thread runs it, so the state must match bit for bit.
  auto run = [](int threads) {
    Scene sc;
    sc.s = settings(24, 2, 20);
    sc.s.threads = threads;
    sc.s.clumping_weight = 0.2f;
    sc.s.accurate_friction = true;
    sc.s.mass_shock = MassShock::Local;
    sc.add_collider(ground());
    unsigned seed = 12345;
    auto rnd = [&] {
      seed = seed * 1664525u + 1013904223u;
      return static_cast<float>(seed >> 8) / 16777216.0f;
    };
    for (int a = 0; a < 8; ++a)
      for (int b = 0; b < 8; ++b)
        for (int c = 0; c < 8; ++c)
          sc.add({0.09f * a + 0.01f * rnd(), 0.06f + 0.09f * b + 0.01f * rnd(),
                  0.09f * c + 0.01f * rnd()},
                 0.04f + 0.01f * rnd());
    sc.s.assume_uniform_radius = false;
    for (int k = 0; k < 40; ++k) sc.substep();
    return sc.P;
  };
  std::vector<float> a = run(1), b = run(2);
  REQUIRE(a.size() == b.size());
  CHECK(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

TEST_CASE("mass-shock scaling lowers a tall stack's residual penetration", "[grains][massshock]") {
  // With mass-shock, each pair's correction moves the upper (lighter) grain more, so the
  // ground's push travels up a stack in fewer iterations: for the same iterations the settled
  // stack keeps less overlap. 100 grains, 60 iterations (under the 2x stacking-height rule).
  auto residual = [](MassShock mode, float power) {
    GrainsSettings s = settings(24, 4, 60);
    s.mass_shock = mode;
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
  s.mass_shock = MassShock::Global;
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
