// The grains node's sleeping test made on the OpenCL device (kernels/sleep.h, opencl/sleep.cpp):
// the same decisions as the host's, bit for bit, with neither the positions nor the
// velocities coming back for it, its state held on the device between substeps.
#include <catch2/catch.hpp>
#include <string>
#include <vector>

#include "nodes/grains/grains_node.h"
#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/bin_scene.h"
#include "tests/support/support.h"

using namespace grains;

namespace {

// The bin (bin_scene.h), the grains dropped from 2 cm lower, 36 frames, with the default
// sleeping. `pusher`: the ball that sweeps through the pile at 0.7-0.8 s (a moving collider
// wakes the sleepers it reaches). `probe`: an attribute node after the grains node that sets the
// attribute `probed` to that expression each substep.
constexpr int kFrames = 36;

Graph sleep_graph(bool error_control, bool pusher, const char* probe, const char* probed,
                  bool jacobi, bool mesh, bool rebuilds) {
  test::BinScene b;
  b.pusher_mesh = mesh;
  b.jacobi = jacobi;
  b.rebuilds = rebuilds;
  b.drop = 0.12;
  b.pusher = pusher;
  b.probe = probe;
  b.probed = probed;
  b.error_control = error_control;
  b.frames = kFrames;
  b.file = "sleep.json";
  return test::bin_graph(b);
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
  size_t slept_there = 0, held_starts = 0, substeps = 0, carried = 0;
  double received = 0, sent = 0;
};

Run run(bool error_control, bool pusher, const char* probe, const char* probed, bool host_sleep,
        bool jacobi, bool mesh, bool rebuilds) {
  test::ScopedEnv host("GRAINS_OPENCL_HOST_SLEEP", host_sleep ? "1" : "0");
  Simulation sim(sleep_graph(error_control, pusher, probe, probed, jacobi, mesh, rebuilds), 1);
  Run r;
  for (int f = 0; f < kFrames; ++f) {
    sim.step_frame();
    r.frames.push_back(frame_of(sim));
    r.substeps += size_t(r.frames.back().substeps);
  }
  const GrainsSolver* s = test::bin_solver(sim);
  REQUIRE(s);
  r.slept_there = s->slept_on_device();
  r.held_starts = s->held_starts();
  r.received = double(s->device_traffic().received);
  r.sent = double(s->device_traffic().sent);
  r.carried = s->sleep_states_carried();
  return r;
}

}  // namespace

TEST_CASE("use_opencl: the sleeping test made on the device decides as the host's", "[opencl]") {
  // The bin's 36 frames (the grains fall, pile and, from about 0.7 s on, fall asleep), with and
  // without error control, the ball's sweep through the pile, a probe reading every grain's
  // position each substep, and one writing every grain's sleeptime back (halved for 0.05 s)
  // each substep: the host's sleeping test (GRAINS_OPENCL_HOST_SLEEP=1) and
  // the device's give the same positions, velocities and sleeping state after every frame, bit
  // for bit. The device makes every substep's test, those of the ball's sweep too; where no
  // other node reads them, each substep but a frame's first starts from the end held there.
  // With contact_solver jacobi too (its substep chained on the device, jacobi_on_device), with
  // error control and the ball, and with its rows and planes found again every iteration (there
  // too, rebuilds_chain); and the ball as a mesh (a lumpy closed one, whose queries the device
  // makes too: engine/mesh_query.h).
  register_builtin_nodes();
  struct Case {
    bool control, pusher;
    const char* probe;
    const char* probed = "probe";
    bool jacobi = false;
    bool mesh = false;
    bool rebuilds = false;
  };
  // halves every grain's sleeptime from 0.9 s to 0.95 s, else writes it back as it was
  const char* halve = "$ST > 0.9 && $ST < 0.95 ? @sleeptime * 0.5 : @sleeptime";
  for (const Case c :
       {Case{true, false, nullptr}, Case{false, false, nullptr}, Case{true, true, nullptr},
        Case{true, false, "$TX"}, Case{false, false, halve, "sleeptime"},
        Case{true, true, nullptr, "probe", true},
        Case{true, true, nullptr, "probe", true, false, true},
        Case{true, true, nullptr, "probe", false, true}}) {
    INFO("error control " << c.control << ", pusher " << c.pusher << ", probe "
                          << (c.probe ? c.probe : "none") << " into " << c.probed
                          << (c.jacobi ? ", jacobi" : "") << (c.rebuilds ? ", rebuilds" : "")
                          << (c.mesh ? ", a mesh pusher" : ""));
    const bool edits = std::string(c.probed) == "sleeptime";
    const Run host =
        run(c.control, c.pusher, c.probe, c.probed, true, c.jacobi, c.mesh, c.rebuilds);
    const Run device =
        run(c.control, c.pusher, c.probe, c.probed, false, c.jacobi, c.mesh, c.rebuilds);
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
    // error control's substeps that keep their start velocity (the first of a finer step)
    // too (the device's end writes it), and those of the ball's sweep (the device has the
    // colliders that moved wake the sleepers they reach)
    CHECK(device.slept_there == device.substeps);
    // What comes back: the host's test takes each substep's positions and velocities (24 bytes
    // a grain) and its reads along the rows (4); the device's run brings back, once a frame,
    // the positions, the velocities and the test's state (56 bytes a grain), and each substep
    // the box of its end (28 bytes for each of 64 work-items), whether a grain's sleep changed
    // (4 bytes) and, with error control, its motion measure of that end (16 bytes for each of
    // 64 work-items)
    const double saved = host.received - device.received;
    INFO(device.substeps << " substeps, " << device.slept_there << " slept there, "
                         << device.carried << " carried, " << device.held_starts
                         << " started there, " << saved / (1000.0 * S)
                         << " bytes a grain a substep less");
    // The test's state that the node gives the device (not held there: the frame's reader or
    // another node fetched it) is carried there instead where it is what came back, grain for
    // grain through the substep's order (GrainsSolver::carry_sleep): every frame's first
    // substep but the run's first; with the probe that writes sleeptime back each substep,
    // every substep but the run's first and those after the probe halved it (5 of them: 0.9 s
    // < k / 96 s < 0.95 s).
    if (!c.pusher && !edits) CHECK(device.carried == kFrames - 1);
    if (edits) {
      CHECK(device.carried + 1 + 5 >= device.substeps);
      CHECK(device.carried + 2 <= device.substeps);
    }
    // A start carried there in the same order, every grain as the last end wrote it, is the
    // sleeping test's start too: the positions that a probe fetches each substep do not go up
    // again (12 bytes a grain a substep, more than all the host's test sends)
    if (c.probe && !edits) CHECK(device.sent < host.sent);
    // (the probe of sleeptime reads no position: the starts stay held)
    if (c.probe && !edits) {
      CHECK(device.held_starts == 0);
    } else {
      CHECK(device.held_starts + F == S);
    }
    if (!c.probe) {
      CHECK(saved >= 28.0 * 1000.0 * double(device.slept_there) - 56.0 * 1000.0 * F -
                         (1792.0 + 4.0 + (c.control ? 1024.0 : 0.0)) * S);
    }
  }
}
