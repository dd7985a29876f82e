// The grains node's sleeping test made on the OpenCL device (kernels/sleep.h, opencl/sleep.cpp):
// the same decisions as the host's, bit for bit, with neither the positions nor the
// velocities coming back for it, its state held on the device between substeps.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "nodes/grains/grains_node.h"
#include "nodes/grains/opencl/iterations.h"
#include "tests/support/support.h"

using namespace grains;
using json = nlohmann::json;

namespace {

// 1,000 grains of 1 cm dropped in a bin 30 cm wide, 4 substeps a frame (or error control's),
// with use_opencl and the default sleeping. `pusher`: a ball of 4 cm radius that sweeps through
// the pile along x from 0.7 s to 0.8 s of the run, still before and after (a moving collider's
// wake test is the host's). `probe`: an attribute node after the grains node that sets "probe"
// to that expression each substep.
constexpr int kFrames = 36;

Graph sleep_graph(bool error_control, bool pusher, const char* probe) {
  auto plane = [&](const char* name, json normal, json at) {
    return json{{"name", name},
                {"type", "collider"},
                {"params", {{"shape", "plane"}, {"normal", normal}, {"translate", at}}}};
  };
  json nodes =
      json::array({plane("ground", {0, 1, 0}, {0, 0, 0}), plane("xm", {1, 0, 0}, {-0.15, 0, 0}),
                   plane("xp", {-1, 0, 0}, {0.15, 0, 0}), plane("zm", {0, 0, 1}, {0, 0, -0.15}),
                   plane("zp", {0, 0, -1}, {0, 0, 0.15})});
  json colliders = {"ground", "xm", "xp", "zm", "zp"};
  if (pusher) {
    nodes.push_back({{"name", "pusher"},
                     {"type", "collider"},
                     {"params",
                      {{"shape", "sphere"},
                       {"radius", 0.04},
                       {"translate", {"-0.2 + 4 * min(max($ST - 0.7, 0), 0.1)", 0.04, 0}}}}});
    colliders.push_back("pusher");
  }
  nodes.push_back({{"name", "sand"},
                   {"type", "source"},
                   {"params",
                    {{"shape", "box"},
                     {"center", {0, 0.12, 0}},
                     {"size", {0.2, 0.2, 0.2}},
                     {"separation", 0.02},
                     {"jitter", 0.1}}}});
  nodes.push_back({{"name", "gravity"},
                   {"type", "force"},
                   {"inputs", {"sand"}},
                   {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}});
  nodes.push_back(
      {{"name", "grains"},
       {"type", "grains"},
       {"inputs", {"gravity"}},
       {"params",
        {{"particle_separation", 0.02}, {"use_opencl", true}, {"friction_with_particles", 1}}}});
  std::string last = "grains";
  if (probe) {
    nodes.push_back({{"name", "probe"},
                     {"type", "attribute"},
                     {"inputs", {"grains"}},
                     {"params", {{"attribute", "probe"}, {"value", probe}}}});
    last = "probe";
  }
  nodes.push_back(
      {{"name", "solver"},
       {"type", "solver"},
       {"inputs", {last}},
       {"params", {{"substeps", 4}, {"error_control", error_control}, {"colliders", colliders}}}});
  json g = {{"grains_graph", 1}, {"fps", 24}, {"frames", kFrames}, {"seed", 5}, {"nodes", nodes}};
  return test::graph_from(g.dump(), test::source_dir() + "/tests/sleep.json");
}

const GrainsSolver* solver_of(const Simulation& sim) {
  for (const ChainNode& c : sim.object(0).chain)
    if (const GrainsSolver* s = c.impl ? grains_solver(*c.impl) : nullptr) return s;
  return nullptr;
}

// what a frame leaves: positions, velocities and the sleeping test's state, in store order
struct Frame {
  std::vector<float> P, v, time, anchor, accel;
  std::vector<int32_t> contacts;
  int substeps = 0;
};

Frame frame_of(const Simulation& sim) {
  const ParticleStore& pts = sim.object(0).pts;
  const size_t n = pts.size();
  auto floats = [&](const char* name, size_t width) {
    const float* a = width == 3 ? pts.v3_if(name) : pts.f_if(name);
    return a ? std::vector<float>(a, a + width * n) : std::vector<float>();
  };
  Frame f;
  f.P = floats("P", 3), f.v = floats("v", 3), f.time = floats("sleeptime", 1);
  f.anchor = floats("sleepanchor", 3), f.accel = floats("sleepaccel", 3);
  if (const int32_t* c = pts.i_if("sleepcontacts")) f.contacts.assign(c, c + n);
  f.substeps = sim.object(0).stats.substeps;
  return f;
}

struct Run {
  std::vector<Frame> frames;
  size_t slept_there = 0, held_starts = 0, substeps = 0;
  double received = 0;
};

Run run(bool error_control, bool pusher, const char* probe, bool host_sleep) {
  test::ScopedEnv host("GRAINS_OPENCL_HOST_SLEEP", host_sleep ? "1" : "0");
  Simulation sim(sleep_graph(error_control, pusher, probe), 1);
  Run r;
  for (int f = 0; f < kFrames; ++f) {
    sim.step_frame();
    r.frames.push_back(frame_of(sim));
    r.substeps += size_t(r.frames.back().substeps);
  }
  const GrainsSolver* s = solver_of(sim);
  REQUIRE(s);
  r.slept_there = s->slept_on_device();
  r.held_starts = s->held_starts();
  r.received = double(s->device_traffic().received);
  return r;
}

}  // namespace

TEST_CASE("use_opencl: the sleeping test made on the device decides as the host's", "[opencl]") {
  // The bin's 36 frames (the grains fall, pile and, from about 0.7 s on, fall asleep), with and
  // without error control, the ball's sweep through the pile, and the probe reading every
  // grain's position each substep: the host's sleeping test (GRAINS_OPENCL_HOST_SLEEP=1) and
  // the device's give the same positions, velocities and sleeping state after every frame, bit
  // for bit. The device makes every substep's test but those of the ball's sweep, whose wake
  // test is the host's, and, with error control, those of the substeps that keep their start
  // velocity (the first of a finer step); where no other node reads them, each substep but a
  // frame's first starts from the end held there.
  register_builtin_nodes();
  struct Case {
    bool control, pusher;
    const char* probe;
  };
  for (const Case c : {Case{true, false, nullptr}, Case{false, false, nullptr},
                       Case{true, true, nullptr}, Case{true, false, "$TX"}}) {
    INFO("error control " << c.control << ", pusher " << c.pusher << ", probe "
                          << (c.probe ? c.probe : "none"));
    const Run host = run(c.control, c.pusher, c.probe, true);
    const Run device = run(c.control, c.pusher, c.probe, false);
    for (size_t f = 0; f < host.frames.size(); ++f) {
      INFO("frame " << f + 1);
      const Frame& a = host.frames[f];
      const Frame& b = device.frames[f];
      REQUIRE(a.P.size() == 3000);
      CHECK(a.substeps == b.substeps);
      CHECK(a.P == b.P);
      CHECK(a.v == b.v);
      CHECK(a.time == b.time);
      CHECK(a.anchor == b.anchor);
      CHECK(a.accel == b.accel);
      CHECK(a.contacts == b.contacts);
    }
    // grains asleep at the end (a stay of 0.5 s), for the test to decide something
    size_t asleep = 0;
    for (const float t : device.frames.back().time) asleep += t >= 0.5f;
    INFO(asleep << " of 1000 asleep at the end");
    CHECK(asleep >= 100);
    CHECK(host.slept_there == 0);
    const double S = double(device.substeps), F = kFrames;
    if (c.pusher) {
      // the sweep's 2.4 frames on the host, the others on the device
      CHECK(device.slept_there > 0);
      CHECK(device.slept_there <= device.substeps - 8);
    } else if (c.control) {
      // at most 6 substeps a frame keep their start velocity ("use_opencl: the grains node
      // holds its end on the device between substeps")
      CHECK(device.slept_there + 6 * kFrames >= device.substeps);
    } else {
      CHECK(device.slept_there == device.substeps);
    }
    // What comes back: the host's test takes each substep's positions and velocities (24 bytes
    // a grain) and its reads along the rows (4); the device's run brings back, once a frame,
    // the positions, the velocities and the test's state (56 bytes a grain), and each substep
    // the box of its end (28 bytes for each of 64 work-items), whether a grain's sleep changed
    // (4 bytes) and, with error control, its motion measure of that end (16 bytes for each of
    // 64 work-items)
    const double saved = host.received - device.received;
    INFO(device.substeps << " substeps, " << device.slept_there << " slept there, "
                         << device.held_starts << " started there, "
                         << saved / (1000.0 * S) << " bytes a grain a substep less");
    if (c.probe) {
      CHECK(device.held_starts == 0);
    } else if (!c.pusher) {
      CHECK(device.held_starts + F + (c.control ? 2 * 6 * F : 0) >= S);
      CHECK(saved >= 28.0 * 1000.0 * double(device.slept_there) - 56.0 * 1000.0 * F -
                         (1792.0 + 4.0 + (c.control ? 1024.0 : 0.0)) * S);
    }
  }
}
