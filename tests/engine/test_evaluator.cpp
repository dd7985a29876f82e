// The evaluator (DESIGN §3) and the core POP nodes, against closed forms.
#include <catch2/catch.hpp>
#include <cmath>
#include <set>

#include "tests/support/support.h"

using namespace grains;
using grains::test::graph_from;

namespace {

// One point dropped from (0, y0, 0) under gravity, optionally onto a ground plane.
std::string drop_graph(int substeps, double y0, const std::string& extra_nodes = "",
                       const std::string& colliders = "[]") {
  return R"({"grains_graph": 1, "fps": 24, "frames": 24, "nodes": [
    {"name": "p", "type": "source", "params": {"shape": "grid", "size": [0, 0, 0], "center": [0, )" +
         std::to_string(y0) + R"(, 0], "separation": 0.1}},
    {"name": "g", "type": "force", "inputs": ["p"], "params": {"force": [0, -9.81, 0], "ignore_mass": true}},
    )" + extra_nodes + R"(
    {"name": "s", "type": "solver", "inputs": ["g"], "params": {"substeps": )" +
         std::to_string(substeps) + R"(, "colliders": )" + colliders + R"(}}]})";
}

Vec3 point(const Simulation& sim, size_t k = 0) { return load3(sim.object(0).pts.v3_if("P"), k); }
Vec3 velocity(const Simulation& sim, size_t k = 0) {
  return load3(sim.object(0).pts.v3_if("v"), k);
}

}  // namespace

TEST_CASE("free fall matches the closed form at 1, 2 and 7 substeps", "[evaluator][physics]") {
  // y(t) = y0 - g t^2 / 2. The solver integrates a constant force exactly, so the only error is
  // float rounding: about 1e-7 relative per step, far below the 1e-4 bound.
  for (int substeps : {1, 2, 7}) {
    Simulation sim(graph_from(drop_graph(substeps, 10.0)));
    for (int f = 0; f < 24; ++f) sim.step_frame();
    double t = 1.0, exact_drop = 0.5 * 9.81 * t * t;
    double drop = 10.0 - point(sim).y;
    INFO("substeps " << substeps << " drop " << drop);
    CHECK(std::fabs(drop - exact_drop) / exact_drop < 1e-4);
    CHECK(std::fabs(velocity(sim).y + 9.81 * t) / (9.81 * t) < 1e-4);
  }
}

TEST_CASE("a ball bouncing on a plane keeps its restitution", "[evaluator][physics]") {
  // Dropped from h onto a plane with bounce e, it rises to e^2 h. The swept contact is found on
  // the chord of each substep's parabola, which is off by at most g dt^2 / 8 (0.13 mm at
  // dt = 1/96 s): the hit time is off by that over the impact speed, well under 1% of e^2 h.
  const double r = 0.05, h = 1.0;
  for (double e : {0.3, 0.5, 0.8}) {
    std::string ground = R"({"name": "ground", "type": "collider", "params": {"shape": "plane", "bounce": )" +
                         std::to_string(e) + R"(, "friction": 0}},)";
    Simulation sim(graph_from(drop_graph(4, h + r, ground, R"(["ground"])")));
    double peak = -1, prev_vy = 0;
    bool bounced = false;
    for (int f = 0; f < 48 && !(bounced && velocity(sim).y < 0); ++f) {
      sim.step_frame();
      double vy = velocity(sim).y;
      if (prev_vy < 0 && vy > 0) bounced = true;
      if (bounced) peak = std::max(peak, point(sim).y - r);
      prev_vy = vy;
    }
    REQUIRE(bounced);
    // frames sample the flight every 1/24 s: near the top y changes by at most g (1/24)^2 / 8
    double sampling = 9.81 / (24.0 * 24.0) / 8;
    INFO("e " << e << " peak " << peak << " expected " << e * e * h);
    CHECK(std::fabs(peak - e * e * h) < 0.01 * e * e * h + sampling);
  }
}

TEST_CASE("a point on a keyframed moving box is carried", "[evaluator][physics]") {
  // The box slides along x at u = 1 m/s (linear keys). Coulomb friction mu accelerates the
  // resting point at mu g until it matches u, after u / (mu g) = 0.2 s with mu = 0.5; it slips
  // u^2 / (2 mu g) = 0.1 m behind the box meanwhile. After 1 s it moves with the box.
  std::string box = R"({"name": "box", "type": "collider", "params": {"shape": "box", "size": [4, 0.2, 4],
      "friction": 0.5, "bounce": 0,
      "translate": [{"keys": [[0, 0], [10, 10]]}, 0, 0]}},)";
  Simulation sim(graph_from(drop_graph(4, 0.1 + 0.05 + 1e-4, box, R"(["box"])")));
  for (int f = 0; f < 24; ++f) sim.step_frame();
  Vec3 v = velocity(sim), p = point(sim);
  INFO("v " << v.x << " x " << p.x << " y " << p.y);
  CHECK(std::fabs(v.x - 1.0) < 0.01);
  double slip = 1.0 / (2 * 0.5 * 9.81);
  CHECK(std::fabs(p.x - (1.0 - slip)) < 0.02);
  CHECK(std::fabs(p.y - 0.15) < 1e-3);  // resting on top, radius 0.05
}

TEST_CASE("chains run top-down, inputs left to right", "[evaluator]") {
  // The kill removes everything. Below the source it runs after the birth (nothing survives);
  // as a merge's first input it runs before the source of the second input (the birth survives
  // the substep).
  auto graph = [](const std::string& merge_inputs) {
    return R"({"grains_graph": 1, "frames": 1, "nodes": [
      {"name": "src", "type": "source", "params": {"shape": "box", "size": [0.3, 0.3, 0.3], "separation": 0.1}},
      {"name": "k", "type": "kill", "params": {"center": [0, 0, 0], "size": [10, 10, 10]}},
      {"name": "m", "type": "merge", "inputs": )" + merge_inputs + R"(},
      {"name": "s", "type": "solver", "inputs": ["m"]}]})";
  };
  Simulation kill_first(graph_from(graph(R"(["k", "src"])")));
  kill_first.step_frame();
  CHECK(kill_first.object(0).pts.size() == 27);
  Simulation kill_last(graph_from(graph(R"(["src", "k"])")));
  kill_last.step_frame();
  CHECK(kill_last.object(0).pts.size() == 0);
}

TEST_CASE("a node below a source acts on that stream only", "[evaluator]") {
  const char* g = R"({"grains_graph": 1, "fps": 10, "frames": 10, "nodes": [
    {"name": "a", "type": "source", "params": {"shape": "grid", "size": [0, 0, 0], "center": [-1, 0, 0]}},
    {"name": "b", "type": "source", "params": {"shape": "grid", "size": [0, 0, 0], "center": [1, 0, 0]}},
    {"name": "push_a", "type": "force", "inputs": ["a"], "params": {"force": [1, 0, 0]}},
    {"name": "m", "type": "merge", "inputs": ["push_a", "b"]},
    {"name": "lift_all", "type": "force", "inputs": ["m"], "params": {"force": [0, 1, 0]}},
    {"name": "s", "type": "solver", "inputs": ["lift_all"]}]})";
  Simulation sim(graph_from(g));
  for (int f = 0; f < 10; ++f) sim.step_frame();
  const ParticleStore& pts = sim.object(0).pts;
  REQUIRE(pts.size() == 2);
  // unit mass, unit force for 1 s: v = 1 m/s along the pushed axes only
  Vec3 va = load3(pts.v3_if("v"), 0), vb = load3(pts.v3_if("v"), 1);
  CHECK(va.x == Approx(1.0).epsilon(1e-5));
  CHECK(vb.x == 0.0f);
  CHECK(va.y == Approx(1.0).epsilon(1e-5));
  CHECK(vb.y == Approx(1.0).epsilon(1e-5));
}

TEST_CASE("several solvers are separate objects with their own variables", "[evaluator]") {
  // One force node feeds two solvers; expressions read OBJNAME, OBJID, NOBJ and SNOBJ.
  const char* g = R"({"grains_graph": 1, "name": "net", "fps": 10, "frames": 10, "nodes": [
    {"name": "src", "type": "source", "params": {"shape": "grid", "size": [0, 0, 0]}},
    {"name": "f", "type": "force", "inputs": ["src"], "params": {"force": [
        "strcmp($OBJNAME, \"left\") == 0 ? -1 : 1", "$OBJID + 10 * $NOBJ + 100 * $SNOBJ",
        "strcmp($DOPNET, \"net\") == 0 ? $OBJ : -5"]}},
    {"name": "left", "type": "solver", "inputs": ["f"]},
    {"name": "right", "type": "solver", "inputs": ["f"]}]})";
  Simulation sim(graph_from(g));
  REQUIRE(sim.object_count() == 2);
  for (int f = 0; f < 10; ++f) sim.step_frame();
  Vec3 vl = load3(sim.object(0).pts.v3_if("v"), 0), vr = load3(sim.object(1).pts.v3_if("v"), 0);
  CHECK(sim.object(0).name == "left");
  CHECK(vl.x == Approx(-1.0).epsilon(1e-5));
  CHECK(vr.x == Approx(1.0).epsilon(1e-5));
  CHECK(vl.y == Approx(0 + 20 + 200).epsilon(1e-5));
  CHECK(vr.y == Approx(1 + 20 + 200).epsilon(1e-5));
  CHECK(vl.z == Approx(0).margin(1e-6));
  CHECK(vr.z == Approx(1).epsilon(1e-5));
}

TEST_CASE("ALLOBJIDS and ALLOBJNAMES list the objects a node processes", "[evaluator]") {
  // `f` feeds both solvers, `g` only the second: each sees its own list
  const char* g = R"({"grains_graph": 1, "name": "net", "fps": 10, "frames": 1, "nodes": [
    {"name": "src", "type": "source", "params": {"shape": "grid", "size": [0, 0, 0]}},
    {"name": "f", "type": "force", "inputs": ["src"], "params": {"force": [
        "strcmp($ALLOBJNAMES, \"left right\") == 0", "strcmp($ALLOBJIDS, \"0 1\") == 0", 0]}},
    {"name": "src2", "type": "source", "params": {"shape": "grid", "size": [0, 0, 0]}},
    {"name": "g", "type": "force", "inputs": ["src2"], "params": {"force": [
        0, 0, "strcmp($ALLOBJNAMES, \"right\") == 0"]}},
    {"name": "m", "type": "merge", "inputs": ["f", "g"]},
    {"name": "left", "type": "solver", "inputs": ["f"]},
    {"name": "right", "type": "solver", "inputs": ["m"]}]})";
  Simulation sim(graph_from(g));
  sim.step_frame();
  const Vec3 vl = load3(sim.object(0).pts.v3_if("v"), 0);
  CHECK(vl.x > 0);
  CHECK(vl.y > 0);
  // the second object's points: its own from src, then src2's
  const ParticleStore& r = sim.object(1).pts;
  REQUIRE(r.size() == 2);
  CHECK(load3(r.v3_if("v"), 0).x > 0);
  CHECK(load3(r.v3_if("v"), 1).z > 0);
}

TEST_CASE("expressions and keyframes drive parameters every substep", "[evaluator]") {
  // force_x = $ST (t): v_x(T) = T^2 / 2 integrated exactly per substep only if the force were
  // piecewise linear; it is sampled at each substep start, so v_x = sum dt * t_k = dt^2 n(n-1)/2.
  // force_y keyframed 0 -> 2 over 1 s (linear), sampled likewise. force_z: $activation-style
  // previous value: "$forcez + 1" counts substeps (the previous value plus one).
  const char* g = R"({"grains_graph": 1, "fps": 10, "frames": 10, "nodes": [
    {"name": "src", "type": "source", "params": {"shape": "grid", "size": [0, 0, 0]}},
    {"name": "f", "type": "force", "inputs": ["src"], "params": {"force": [
        "$ST", {"keys": [[0, 0], [1, 2]], "interp": "linear"}, "$forcez + 1"]}},
    {"name": "s", "type": "solver", "inputs": ["f"], "params": {"substeps": 2}}]})";
  Simulation sim(graph_from(g));
  for (int f = 0; f < 10; ++f) sim.step_frame();
  Vec3 v = load3(sim.object(0).pts.v3_if("v"), 0);
  int n = 20;
  double dt = 0.05;
  double vx = 0, vy = 0, vz = 0;
  for (int k = 0; k < n; ++k) {
    vx += dt * (k * dt);
    vy += dt * (2 * k * dt);
    vz += dt * (k + 1);
  }
  CHECK(v.x == Approx(vx).epsilon(1e-5));
  CHECK(v.y == Approx(vy).epsilon(1e-5));
  CHECK(v.z == Approx(vz).epsilon(1e-5));
}

TEST_CASE("source fills, packs, births at a rate and sets pscale and mass", "[nodes][source]") {
  const char* g = R"({"grains_graph": 1, "fps": 10, "frames": 10, "seed": 3, "nodes": [
    {"name": "box", "type": "source", "params": {"shape": "box", "size": [1, 1, 1], "separation": 0.25, "density": 1000}},
    {"name": "ball", "type": "source", "params": {"shape": "sphere", "radius": 0.5, "separation": 0.1,
        "center": [5, 0, 0], "packing": "hexagonal", "birth_frame": 3, "velocity": [0, 2, 0]}},
    {"name": "rain", "type": "source", "params": {"emission": "rate", "rate": 50, "start_frame": 1, "end_frame": 4,
        "center": [-5, 0, 0], "size": [1, 0, 1], "shape": "grid", "group": "drops"}},
    {"name": "m", "type": "merge", "inputs": ["box", "ball", "rain"]},
    {"name": "s", "type": "solver", "inputs": ["m"]}]})";
  Simulation sim(graph_from(g));
  sim.step_frame();
  const ParticleStore& pts = sim.object(0).pts;
  // a 1 m box at 0.25 m: 4 per side
  size_t box = 64, rain_first = 5;  // 50/s for 0.1 s
  CHECK(pts.size() == box + rain_first);
  CHECK(pts.f_if("pscale")[0] == Approx(0.125));
  CHECK(pts.f_if("mass")[0] == Approx(1000 * 4.0 / 3.0 * M_PI * std::pow(0.125, 3)).epsilon(1e-5));
  for (int f = 1; f < 10; ++f) sim.step_frame();
  size_t rain = 50 * 4 / 10;  // frames 1..4 of 0.1 s
  const ParticleStore& after = sim.object(0).pts;
  // hexagonal close packing fills a ball at about 0.74 / (4/3 pi (s/2)^3) per unit volume
  size_t ball = after.size() - box - rain;
  double expected = 0.7405 * (4.0 / 3.0 * M_PI * 0.125) / (4.0 / 3.0 * M_PI * std::pow(0.05, 3));
  INFO("ball " << ball << " expected about " << expected);
  CHECK(std::fabs(ball - expected) / expected < 0.1);  // surface effects on a 10-grain radius
  // ids unique
  std::set<int> ids(after.i_if("id"), after.i_if("id") + after.size());
  CHECK(ids.size() == after.size());
  size_t drops = 0;
  for (size_t k = 0; k < after.size(); ++k) drops += after.in_group("drops", k);
  CHECK(drops == rain);
}

TEST_CASE("group by region and by attribute", "[nodes][group]") {
  const char* g = R"({"grains_graph": 1, "fps": 10, "frames": 1, "nodes": [
    {"name": "src", "type": "source", "params": {"shape": "box", "size": [1, 1, 1], "separation": 0.25}},
    {"name": "top", "type": "group", "inputs": ["src"], "params": {"group_name": "top", "rule": "attribute",
        "attribute": "P_y", "compare": ">", "value": 0}},
    {"name": "ball", "type": "group", "inputs": ["top"], "params": {"group_name": "ball", "rule": "sphere", "radius": 0.3}},
    {"name": "push", "type": "force", "inputs": ["ball"], "params": {"group": "top", "force": [0, 10, 0]}},
    {"name": "s", "type": "solver", "inputs": ["push"]}]})";
  Simulation sim(graph_from(g));
  sim.step_frame();
  const ParticleStore& pts = sim.object(0).pts;
  size_t top = 0, ball = 0;
  for (size_t k = 0; k < pts.size(); ++k) {
    Vec3 rest = load3(pts.v3_if("rest"), k);
    bool is_top = rest.y > 0;
    CHECK(pts.in_group("top", k) == is_top);
    CHECK(pts.in_group("ball", k) == (length(rest) <= 0.3f));
    CHECK((load3(pts.v3_if("v"), k).y > 0) == is_top);
    top += is_top;
    ball += pts.in_group("ball", k);
  }
  CHECK(top == 32);
  CHECK(ball == 8);
}

TEST_CASE("drag pulls the velocity towards the wind", "[nodes][force]") {
  // dv/dt = -(k/m)(v - w): v(t) = w + (v0 - w) e^{-k t / m}; the force is sampled at each substep
  // start (explicit), so the discrete factor per substep is (1 - k dt / m).
  const char* g = R"({"grains_graph": 1, "fps": 10, "frames": 10, "nodes": [
    {"name": "src", "type": "source", "params": {"shape": "grid", "size": [0, 0, 0], "velocity": [5, 0, 0]}},
    {"name": "d", "type": "force", "inputs": ["src"], "params": {"drag": 2, "wind": [1, 0, 0]}},
    {"name": "s", "type": "solver", "inputs": ["d"], "params": {"substeps": 10}}]})";
  Simulation sim(graph_from(g));
  for (int f = 0; f < 10; ++f) sim.step_frame();
  double v = 1 + 4 * std::pow(1 - 2 * 0.01, 100);
  CHECK(load3(sim.object(0).pts.v3_if("v"), 0).x == Approx(v).epsilon(1e-4));
}
