// Collision feedback and impact data (help page "Enable Collision Feedback", "Add Impact Data").
// Both measure the momentum a collider gives a grain: its applied corrections dx_c over a substep
// change the grain's velocity by dx_c / dt (v = (p - P) / dt), the final collision pass by the
// velocity it removes; the collider receives the opposite.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "engine/frame_writer.h"
#include "tests/nodes/grains/bin_scene.h"
#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;
using json = nlohmann::json;

namespace {

Graph graph(const json& nodes) {
  json g = {{"grains_graph", 1}, {"fps", 24}, {"frames", 48}, {"seed", 1}, {"nodes", nodes}};
  return test::graph_from(g.dump(), test::source_dir() + "/tests/feedback.json");
}

json ground_node() {
  return {{"name", "ground"}, {"type", "collider"}, {"params", {{"shape", "plane"}}}};
}

// a source's block (its parameters) under gravity, a grains node (its parameters), the ground
// and a solver of `substeps` substeps
Graph block_on_ground(const json& source, const json& grains, int substeps) {
  return graph({{{"name", "src"}, {"type", "source"}, {"params", source}},
                {{"name", "grav"},
                 {"type", "force"},
                 {"inputs", {"src"}},
                 {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}},
                {{"name", "n"}, {"type", "grains"}, {"inputs", {"grav"}}, {"params", grains}},
                ground_node(),
                {{"name", "s"},
                 {"type", "solver"},
                 {"inputs", {"n"}},
                 {"params", {{"substeps", substeps}, {"colliders", {"ground"}}}}}});
}

// use_opencl: the device makes the impact data at its end of the substep, so the grains node
// reads no position and every end stays there (its positions and velocities come back once a
// frame, when the frame reads them)
void check_held(const Simulation& sim, int substeps) {
  const GrainsSolver* solver = test::bin_solver(sim);
  REQUIRE(solver);
  CHECK(solver->held_ends() == size_t(substeps));
}

// (use_opencl: on the OpenCL device, whose end of the substep makes the impact data there)
void resting_pile(bool opencl) {
  // A 5 x 3 x 5 block of 75 grains of 0.2 kg settles on the ground. At rest every substep
  // gravity gives the pile sum(m) g dt of downward momentum and only the ground takes it back,
  // so the ground's mean force over a frame is sum(m) g = 75 * 0.2 * 9.81 = 147.15 N.
  // The balance holds when the grains' pair corrections conserve momentum, which is what
  // disable_constraint_averaging is for (help page): with averaging, a pair's two corrections are
  // divided by the two grains' different contact counts and create momentum between them (this
  // 3-layer pile then reads 0.87 of its weight). So the test disables averaging, with the
  // weights the help page asks for (0.5). Tolerance 2%: what is left of the settling motion.
  Graph g = block_on_ground(
      {{"size", {0.5, 0.3, 0.5}}, {"separation", 0.1}, {"center", {0, 0.2, 0}}, {"mass", 0.2}},
      {{"constraint_iterations", 20},
       {"enable_collision_feedback", true},
       {"disable_constraint_averaging", true},
       {"internal_collisions_weight", 0.5},
       {"friction_with_particles", 0.5},
       {"use_opencl", opencl}},
      4);
  Simulation sim(g, 2);
  std::string dir = test::temp_dir("feedback");
  FrameWriter w(dir, {});
  double sum_fy = 0, sum_fx = 0, sum_tx = 0;
  int frames = 0, substeps = 0;
  for (int f = 1; f <= 48; ++f) {
    sim.step_frame();
    substeps += sim.object(0).stats.substeps;
    const FrameStats& st = sim.object(0).stats;
    w.write(frame_output(f, sim.object(0), false));
    REQUIRE(st.colliders.size() == 1);
    if (f <= 36) continue;  // settled after 1.5 s
    sum_fy += st.colliders[0].force.y;
    sum_fx += st.colliders[0].force.x;
    sum_tx += st.colliders[0].torque.x;
    ++frames;
  }
  const double weight = 75 * 0.2 * kG;
  double fy = -sum_fy / frames;  // the ground is pushed down
  report(opencl ? "feedback (use_opencl): ground force / pile weight"
                : "feedback: ground force / pile weight",
         fy / weight);
  CHECK(std::fabs(fy - weight) < 0.02 * weight);
  // the block is centred on the collider's origin: no sideways force, torque ~ 0 (a lever arm of
  // ~2% of the 0.5 m block would be 0.01 m)
  CHECK(std::fabs(sum_fx / frames) < 0.02 * weight);
  CHECK(std::fabs(sum_tx / frames) < 0.01 * weight);
  // DIR/colliders.csv: a header and one row per frame
  std::string csv = test::read_text(dir + "/colliders.csv");
  CHECK(csv.rfind("frame,time,collider,fx,fy,fz,tx,ty,tz\n", 0) == 0);
  CHECK(std::count(csv.begin(), csv.end(), '\n') == 49);
  CHECK(csv.find("\n48,2.0,ground,") != std::string::npos);  // floats always as floats
  if (opencl) check_held(sim, substeps);
}

void dropped_grain(bool opencl) {
  // One grain of 0.5 kg dropped from 1 m falls on the ground, stops and rests. Over the run its
  // momentum changes by m (v_end - v_0) = m v_end (v_0 = 0) while gravity gives -m g T, so the
  // ground's impulse is J = m v_end + m g T (normal component). The sum of impactimpulse over
  // the frames must match to 2% (it is the same accounting, up to float rounding: ~1e-5).
  Graph g = block_on_ground(
      {{"size", {0.1, 0.1, 0.1}}, {"separation", 0.1}, {"center", {0, 1, 0}}, {"mass", 0.5}},
      {{"add_impact_data", true}, {"use_opencl", opencl}}, 2);
  Simulation sim(g, 2);
  double J = 0;
  int first_hit = 0, substeps = 0;
  for (int f = 1; f <= 48; ++f) {
    sim.step_frame();
    substeps += sim.object(0).stats.substeps;
    const ParticleStore& s = sim.object(0).pts;
    REQUIRE(s.size() == 1);
    if (s.i_if("impact")[0]) {
      if (!first_hit) {
        first_hit = f;
        CHECK(s.i_if("impactother")[0] == 0);
        Vec3 n = load3(s.v3_if("impactN"), 0), x = load3(s.v3_if("impactP"), 0);
        CHECK(n.y == Approx(1.0f));
        CHECK(std::fabs(x.y) < 1e-4f);  // on the ground's surface
      }
      J += s.f_if("impactimpulse")[0];
    }
  }
  const ParticleStore& s = sim.object(0).pts;
  const double T = 2.0, m = 0.5;
  double expected = m * load3(s.v3_if("v"), 0).y + m * kG * T;
  report(opencl ? "impacts (use_opencl): sum impactimpulse / momentum change"
                : "impacts: sum impactimpulse / momentum change",
         J / expected);
  report(opencl ? "impacts (use_opencl): first frame with an impact"
                : "impacts: first frame with an impact",
         first_hit);
  CHECK(first_hit > 8);   // free fall from 0.95 m takes 0.44 s = 10.5 frames
  CHECK(first_hit < 13);
  CHECK(std::fabs(J - expected) < 0.02 * expected);
  if (opencl) check_held(sim, substeps);
}

}  // namespace

TEST_CASE("collision feedback: a resting pile presses on the ground with its weight",
          "[grains][feedback]") {
  resting_pile(false);
}

TEST_CASE("use_opencl: collision feedback from the device's impact data", "[opencl][feedback]") {
  resting_pile(true);
}

TEST_CASE("impact data: a dropped grain's impact impulses sum to its momentum change",
          "[grains][impacts]") {
  dropped_grain(false);
}

TEST_CASE("use_opencl: a dropped grain's impact impulses from the device", "[opencl][impacts]") {
  dropped_grain(true);
}

TEST_CASE("impact data: a plane row rebuilt during the iterations keeps each collider's impulse",
          "[grains][impacts][colliders]") {
  // Grain A (r = 5 cm, 1 kg) sits in the corner of the ground and a wall (face x = 0), 2 cm into
  // the ground and 1 cm into the wall, so its plane row, nearest first, is (ground, wall). Grain
  // B, 20 times heavier, overlaps it by 3 cm from -x and keeps pushing it into the wall, so from
  // the first iteration on A is nearer the wall and a row rebuilt then is (wall, ground). A slides
  // along z at 1 m/s, so the friction pass acts on both planes. The rebuilt rows hold the same
  // two infinite planes as the row found once, so the grains move the same up to float rounding,
  // and so must each collider's impulse: the iterations' applied corrections and the friction
  // pass's overlap sums follow their collider through a rebuild, not their slot in the row.
  // Tolerance: 1e-4 of the largest impulse component, against float rounding of ~1e-6; a sum
  // left in its slot gives the ground the wall's share, a difference of order 1.
  struct Result {
    Vec3 a, j_ground, j_wall;
    int32_t first_slot = -2;
  };
  auto run = [](bool update) {
    GrainsSettings s = settings(24, 1, 10);
    s.contact_solver = kContactJacobi;  // its plane rows, rebuilt during the iterations
    s.update_collisions_during_iterations = update;
    s.final_collision_test = false;
    s.accurate_friction = false;
    s.friction_with_colliders = 1.0f;
    s.friction_with_particles = 0;
    Scene sc;
    sc.s = s;
    sc.gravity = {0, 0, 0};
    sc.add_collider(ground());
    sc.add_collider(box({0.5f, 0, 0}, {1, 2, 2}));  // wall face at x = 0
    sc.add({-0.04f, 0.03f, 0}, 0.05f, 1.0f, {0, 0, 1});
    sc.add({-0.11f, 0.03f, 0}, 0.05f, 20.0f, {0, 0, 1});
    for (ColliderState& c : sc.colliders) c.dt = s.dt;
    const size_t slots = GrainsSolver::kContactSlots * sc.size();
    std::vector<float> impulse(3 * slots), point(3 * slots), normal(3 * slots);
    std::vector<int32_t> collider(slots);
    GrainsData d = sc.data();
    d.impact_impulse = impulse.data();
    d.impact_point = point.data();
    d.impact_normal = normal.data();
    d.impact_collider = collider.data();
    sc.solver.substep(d, s, sc.colliders.data(), sc.colliders.size(), &sc.stats);
    Result r;
    r.a = sc.pos(0);
    r.first_slot = collider[0];
    for (size_t q = 0; q < GrainsSolver::kContactSlots; ++q) {
      Vec3 j = load3(impulse.data(), q);
      if (collider[q] == 0) r.j_ground += j;
      if (collider[q] == 1) r.j_wall += j;
    }
    return r;
  };
  Result once = run(false), every = run(true);
  auto report3 = [](const std::string& what, const Vec3& j) {
    report((what + " x").c_str(), j.x);
    report((what + " y").c_str(), j.y);
    report((what + " z").c_str(), j.z);
  };
  report3("impulse, rows found once: ground", once.j_ground);
  report3("impulse, rows found once: wall", once.j_wall);
  report3("impulse, rows rebuilt: ground", every.j_ground);
  report3("impulse, rows rebuilt: wall", every.j_wall);
  // the premise: the rebuilt row ends wall first, the row found once ground first
  REQUIRE(once.first_slot == 0);
  REQUIRE(every.first_slot == 1);
  // both planes gave momentum, along their normals and against the sliding (friction)
  CHECK(once.j_ground.y > 0);
  CHECK(once.j_wall.x < 0);
  CHECK(once.j_ground.z < 0);
  CHECK(once.j_wall.z < 0);
  CHECK(length(every.a - once.a) < 1e-5f);
  float scale = std::max({std::fabs(once.j_ground.x), std::fabs(once.j_ground.y), std::fabs(once.j_ground.z),
                          std::fabs(once.j_wall.x), std::fabs(once.j_wall.y), std::fabs(once.j_wall.z)});
  CHECK(length(every.j_ground - once.j_ground) < 1e-4f * scale);
  CHECK(length(every.j_wall - once.j_wall) < 1e-4f * scale);
}
