// Pins (help page "Targets (Pins)") and the target node (KeyframedGrains, TargetSand). The
// tolerances follow from the pin's per-iteration fraction f = min(1, k / (substeps x iterations)):
// a lone pinned grain keeps q = (1 - f)^I of its distance to the target after a substep's I
// iterations.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "engine/cook.h"
#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;
using json = nlohmann::json;

namespace {

// The steady sag of a pinned grain under an acceleration a (gravity, or the target's own):
// each substep the prediction moves it a dt^2 off, the iterations leave q of (e + a dt^2), so
// e = q (e + a dt^2), e = q / (1 - q) a dt^2.
double pin_lag(double k, int substeps, int iterations, double a, double dt) {
  double f = std::min(1.0, k / (substeps * iterations));
  double q = std::pow(1.0 - f, iterations);
  return q / (1.0 - q) * a * dt * dt;
}

Graph graph(const json& nodes, int frames = 48) {
  json g = {{"grains_graph", 1}, {"fps", 24}, {"frames", frames}, {"seed", 1}, {"nodes", nodes}};
  return test::graph_from(g.dump(), test::source_dir() + "/tests/pins.json");
}

// A grain pinned with k = 4 at 4 substeps x 10 iterations, run 2 s under gravity: its steady sag
// must be q / (1 - q) g dt^2 within 1%. Returns the scene.
Scene check_pinned_sag(bool opencl, int contact_solver = kContactGaussSeidel) {
  // f = 0.1, q = 0.9^10 = 0.349, dt = 1/96 s: e = 0.535 g dt^2 = 0.57 mm. Steady state after 2 s
  // (the transient decays by sqrt(q) per substep); float rounding is far below 1%, so 1% of e.
  Scene sc;
  sc.s = settings(24, 4, 10);
  sc.s.target_stiffness = 4;
  sc.s.use_opencl = opencl;
  sc.s.contact_solver = contact_solver;
  sc.add({0, 1, 0}, 0.05f);
  sc.targetP.resize(3, 0.0f);
  sc.targetP[1] = 1.0f;
  sc.targetstiffness.resize(1, 1.0f);
  sc.run(2.0f);
  double e = 1.0 - sc.pos(0).y;
  double expected = pin_lag(4, 4, 10, kG, sc.s.dt);
  report(opencl ? "pinned grain sag on the device / (q/(1-q) g dt^2)" : "pinned grain sag / (q/(1-q) g dt^2)",
         e / expected);
  CHECK(std::fabs(e - expected) < 0.01 * expected);
  return sc;
}

}  // namespace

TEST_CASE("a pinned grain sags by q/(1-q) g dt^2 under gravity", "[grains][pins]") {
  Scene sc = check_pinned_sag(false);
  // the weight halves the fraction: weight 0.5 x stiffness 4 is not stiffness 2 (weights are not
  // scaled by iterations), but with weight 0 the grain falls freely
  Scene off = sc;
  off.s.target_weight = 0;
  off.run(0.5f);
  CHECK(off.pos(0).y < 1.0f - 0.5f * kG * 0.25f * 0.9f);
}

TEST_CASE("use_opencl: a pinned grain sags by q/(1-q) g dt^2 on the OpenCL device",
          "[grains][pins][opencl]") {
  // the passes and the pins on PoCL's CPU device, with either contact solver: the same steady
  // sag within the same 1%
  check_pinned_sag(true);
  check_pinned_sag(true, kContactJacobi);
}

TEST_CASE("no targetstiffness attribute means no pin", "[grains][pins]") {
  // help page: "If no targetstiffness point attribute is present, it is treated as zero". A
  // grain with targetP at its start and no targetstiffness falls freely: after 1 s at 24 fps x 2
  // substeps semi-implicit Euler moves it g dt^2 k (k + 1) / 2, k = 48 (within float rounding).
  auto make = [] {
    ParticleStore s;
    s.add_points(1);
    store3(s.v3("P"), 0, Vec3{0, 1, 0});
    store3(s.v3("targetP"), 0, Vec3{0, 1, 0});
    s.f("pscale")[0] = 0.05f;
    return s;
  };
  CookOptions o;
  o.substeps = 2;
  o.frames = 24;
  ParticleStore free = make();
  // a force node cannot run in the same cook: gravity comes from the grains' own force attribute
  // being cleared each substep, so use the `force` node then `grains` through a graph instead
  Graph g = graph({{{"name", "g"}, {"type", "force"}, {"params", {{"force", {0, -9.81, 0}}}}},
                   {{"name", "n"}, {"type", "grains"}, {"inputs", {"g"}}, {"params", json::object()}},
                   {{"name", "s"}, {"type", "solver"}, {"inputs", {"n"}}, {"params", {{"substeps", 2}, {"error_control", false}}}}});
  auto run = [&](ParticleStore pts) {
    Simulation sim(g, 2);
    sim.set_points(0, std::move(pts));
    for (int f = 0; f < 24; ++f) sim.step_frame();
    return load3(sim.object(0).pts.v3("P"), 0).y;
  };
  const double dt = 1.0 / 48, k = 48;
  float y_free = run(make());
  CHECK(std::fabs((1.0 - y_free) - kG * dt * dt * k * (k + 1) / 2) < 1e-3);
  ParticleStore pinned = make();
  pinned.f("targetstiffness")[0] = 1.0f;  // x target_stiffness 1000: the full fraction
  float y_pinned = run(std::move(pinned));
  // f = 1: the pin puts the grain back on its target every iteration; it moves 0
  CHECK(std::fabs(y_pinned - 1.0f) < 1e-5f);
  report("unpinned drop in 1 s (m)", 1.0 - y_free);
}

TEST_CASE("a puppet of grains follows its keyframed target within the pin lag", "[grains][pins][target]") {
  // KeyframedGrains: a 4 x 4 x 4 block (pscale 0.045 at separation 0.1, so its grains never
  // touch and only the pins act) pinned through the target node to its rest shape, translated by
  // x = 0.5 sin(2 T) and turned about y by keyframes 0 -> 90 deg over 2 s. Gravity pulls it.
  // Target acceleration: 0.5 * 4 = 2 m/s^2 plus the turn's centripetal (pi/4)^2 * 0.3 = 0.2,
  // with gravity |a| <= 12.1 m/s^2. The quasi-static lag is pin_lag(k, a); the forcing varies
  // over ~pi s, much slower than the pin's response (sqrt(q) per substep), so it holds to well
  // within 1.5x once the start-up transient (0.5 s) is gone.
  const double k = 4;
  Graph g = graph({{{"name", "src"}, {"type", "source"},
                    {"params", {{"size", {0.4, 0.4, 0.4}}, {"separation", 0.1}, {"pscale", 0.045},
                                {"center", {0, 1, 0}}}}},
                   {{"name", "grav"}, {"type", "force"}, {"inputs", {"src"}},
                    {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}},
                   {{"name", "t"}, {"type", "target"}, {"inputs", {"grav"}},
                    {"params", {{"translate", {"0.5 * sin(2 * $T)", 0, 0}},
                                {"rotate", {0, {{"keys", {{0, 0}, {2, 90}}}}, 0}},
                                {"pivot", {0, 1, 0}}}}},
                   {{"name", "n"}, {"type", "grains"}, {"inputs", {"t"}},
                    {"params", {{"target_stiffness", k}, {"constraint_iterations", 10}}}},
                   {{"name", "s"}, {"type", "solver"}, {"inputs", {"n"}}, {"params", {{"substeps", 4}}}}});
  Simulation sim(g, 2);
  const double dt = 1.0 / 96;
  const double bound = 1.5 * pin_lag(k, 4, 10, 12.1, dt);
  double worst = 0, moved = 0;
  for (int f = 1; f <= 48; ++f) {
    sim.step_frame();
    if (f <= 12) continue;
    const ParticleStore& s = sim.object(0).pts;
    const float* P = s.v3_if("P");
    const float* T = s.v3_if("targetP");
    const float* rest = s.v3_if("rest");
    for (size_t i = 0; i < s.size(); ++i) {
      worst = std::max(worst, static_cast<double>(length(load3(P, i) - load3(T, i))));
      moved = std::max(moved, static_cast<double>(length(load3(P, i) - load3(rest, i))));
    }
  }
  report("puppet: worst lag (m)", worst);
  report("puppet: lag bound 1.5 q/(1-q) |a| dt^2 (m)", bound);
  CHECK(sim.object(0).pts.size() == 64);
  CHECK(moved > 0.3);  // it really was puppeteered
  CHECK(worst < bound);
}

TEST_CASE("TargetSand: grains converge onto a mesh surface", "[grains][pins][target]") {
  // 343 grains (r = 0.02) in a 1.4 m cloud around a unit cube mesh, inside and outside it (tests/data/target_cube.obj,
  // area 6 m^2 holds ~3,700 such grains in one layer, so they fit without stacking). The target
  // node sets targetP to the closest surface point; the grains node pins with the full fraction.
  // No gravity. A grain is settled on the surface when its centre is within r of it (its
  // contacts may hold it off by up to about a radius where they crowd, e.g. at edges).
  Graph g = graph({{{"name", "src"}, {"type", "source"},
                    {"params", {{"size", {1.4, 1.4, 1.4}}, {"separation", 0.2}, {"pscale", 0.02},
                                {"jitter", 0.3}}}},
                   {{"name", "t"}, {"type", "target"}, {"inputs", {"src"}},
                    {"params", {{"mode", "surface"}, {"file", "data/target_cube.obj"}}}},
                   {{"name", "n"}, {"type", "grains"}, {"inputs", {"t"}},
                    {"params", {{"constraint_iterations", 10}}}},
                   {{"name", "s"}, {"type", "solver"}, {"inputs", {"n"}}, {"params", {{"substeps", 2}}}}});
  Simulation sim(g, 2);
  for (int f = 0; f < 24; ++f) sim.step_frame();
  const ParticleStore& s = sim.object(0).pts;
  const float* P = s.v3_if("P");
  double worst = 0, mean = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    Vec3 x = load3(P, i);
    // distance to the surface of the cube [-0.5, 0.5]^3
    Vec3 a{std::fabs(x.x), std::fabs(x.y), std::fabs(x.z)};
    float m = std::max(a.x, std::max(a.y, a.z));
    double dist = m <= 0.5f ? 0.5 - m
                            : length(Vec3{std::max(a.x - 0.5f, 0.0f), std::max(a.y - 0.5f, 0.0f),
                                          std::max(a.z - 0.5f, 0.0f)});
    worst = std::max(worst, dist);
    mean += dist;
  }
  mean /= s.size();
  report("TargetSand: grains", s.size());
  report("TargetSand: worst distance to the surface / r", worst / 0.02);
  report("TargetSand: mean distance to the surface / r", mean / 0.02);
  CHECK(s.size() == 343);
  CHECK(worst < 0.02);
  CHECK(mean < 0.1 * 0.02);
}

TEST_CASE("target node: a missing surface file is a load error", "[target]") {
  json g = {{"grains_graph", 1}, {"fps", 24}, {"frames", 1},
            {"nodes", {{{"name", "src"}, {"type", "source"}, {"params", json::object()}},
                       {{"name", "t"}, {"type", "target"}, {"inputs", {"src"}},
                        {"params", {{"mode", "surface"}, {"file", "data/no_such_mesh.obj"}}}},
                       {{"name", "s"}, {"type", "solver"}, {"inputs", {"t"}}, {"params", json::object()}}}}};
  CHECK_THROWS(test::graph_from(g.dump(), test::source_dir() + "/tests/pins.json"));
}

TEST_CASE("a fully stiff pin holds its grain while a column of free grains presses on it",
          "[grains][pins]") {
  // target_stiffness 100 over substeps x iterations = 4 x 10 is a full pull every iteration, so
  // a pinned grain ends each iteration on its target whatever presses on it: the pins are their
  // own constraint group after the averaged contacts. Averaged in as one of the grain's counts,
  // the pin gave way to the 10-grain column standing on it by 1.97 mm (and a KeyframedGrains
  // interior lagged its target by 9 mm where its skin pressed). Held to float rounding at 1 m:
  // 1e-6 m.
  Scene sc;
  sc.s = settings(24, 4, 10);
  sc.s.target_stiffness = 100;
  const float r = 0.05f;
  sc.add({0, 1, 0}, r);
  for (int k = 1; k <= 10; ++k) sc.add({0, 1 + 2 * r * k, 0}, r);
  sc.targetP.assign(3 * sc.size(), 0.0f);
  sc.targetP[1] = 1.0f;
  sc.targetstiffness.assign(sc.size(), 0.0f);
  sc.targetstiffness[0] = 1.0f;
  sc.run(1.0f);
  const float lag = length(sc.pos(0) - Vec3{0, 1, 0});
  report("pinned grain under a column: lag (m)", lag);
  CHECK(lag < 1e-6f);
  // and the column stands on it, its lowest grain above it rather than pushed past or aside
  CHECK(sc.pos(1).y > 1 + r);
  CHECK(std::fabs(sc.pos(1).x) < 0.1f * r);
}
