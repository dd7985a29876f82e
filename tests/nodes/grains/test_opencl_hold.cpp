// A grains node's substep end held on the OpenCL device between the substeps of a frame
// (GrainsData::may_hold_end, the store's held attributes in engine/particles.h): the positions
// and velocities come back once a frame, or when another node reads them, and the frames are
// the same bits as when they come back every substep.
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

// 1,000 grains of 1 cm dropped in a bin 30 cm wide, its floor at height 0 and its centre
// `far` from the world's origin along x and z, 4 substeps a frame (or error control's), with
// use_opencl and no sleeping (whose test reads the positions every substep). With `probe` an
// attribute node after the grains node sets the attribute "probe" to that expression each
// substep: "$TX" reads every grain's position, which brings them back each time.
Graph bin_graph(const char* probe, bool error_control, float far) {
  auto plane = [&](const char* name, json normal, json at) {
    return json{{"name", name},
                {"type", "collider"},
                {"params", {{"shape", "plane"}, {"normal", normal}, {"translate", at}}}};
  };
  json nodes = json::array(
      {plane("ground", {0, 1, 0}, {far, 0, far}), plane("xm", {1, 0, 0}, {far - 0.15, 0, far}),
       plane("xp", {-1, 0, 0}, {far + 0.15, 0, far}), plane("zm", {0, 0, 1}, {far, 0, far - 0.15}),
       plane("zp", {0, 0, -1}, {far, 0, far + 0.15})});
  nodes.push_back({{"name", "sand"},
                   {"type", "source"},
                   {"params",
                    {{"shape", "box"},
                     {"center", {far, 0.15, far}},
                     {"size", {0.2, 0.2, 0.2}},
                     {"separation", 0.02},
                     {"jitter", 0.1}}}});
  nodes.push_back({{"name", "gravity"},
                   {"type", "force"},
                   {"inputs", {"sand"}},
                   {"params", {{"force", {0, -9.81, 0}}, {"ignore_mass", true}}}});
  nodes.push_back({{"name", "grains"},
                   {"type", "grains"},
                   {"inputs", {"gravity"}},
                   {"params",
                    {{"particle_separation", 0.02},
                     {"use_opencl", true},
                     {"sleep_speed", 0},
                     {"friction_with_particles", 1}}}});
  std::string last = "grains";
  if (probe) {
    nodes.push_back({{"name", "probe"},
                     {"type", "attribute"},
                     {"inputs", {"grains"}},
                     {"params", {{"attribute", "probe"}, {"value", probe}}}});
    last = "probe";
  }
  nodes.push_back({{"name", "solver"},
                   {"type", "solver"},
                   {"inputs", {last}},
                   {"params",
                    {{"substeps", 4},
                     {"error_control", error_control},
                     {"colliders", {"ground", "xm", "xp", "zm", "zp"}}}}});
  json g = {{"grains_graph", 1}, {"fps", 24}, {"frames", 8}, {"seed", 5}, {"nodes", nodes}};
  return test::graph_from(g.dump(), test::source_dir() + "/tests/hold.json");
}

const GrainsSolver* solver_of(const Simulation& sim) {
  for (const ChainNode& c : sim.object(0).chain)
    if (const GrainsSolver* s = c.impl ? grains_solver(*c.impl) : nullptr) return s;
  return nullptr;
}

std::vector<float> array(const Simulation& sim, const char* name) {
  const ParticleStore& pts = sim.object(0).pts;
  const float* a = pts.v3_if(name);
  return std::vector<float>(a, a + 3 * pts.size());
}

}  // namespace

TEST_CASE("use_opencl: the grains node holds its end on the device between substeps", "[opencl]") {
  // The bin's 8 frames (the grains fall, land and pile), with and without the probe, without
  // and with error control, at the world's origin and 96 m from it (the substep's origin,
  // which a held start takes from the box the device measured, is then not 0): the same
  // positions and velocities after every frame, bit for bit. Without the probe, or with one
  // that reads no position or velocity ($ID x 2), every substep
  // but a frame's first (where the node sorts its grains again) starts from the end held
  // there, and the 24 bytes a grain of each such end do not come back, with error control too,
  // whose motion measure is made there (Node::held_motion; 16 bytes for each of 64 work-items
  // come back instead). With the probe no start is held. A probe that reads every velocity
  // ($VX) has the host make the motion measure: the same frames, the same substeps.
  register_builtin_nodes();
  for (const bool control : {false, true})
    for (const float far : {0.0f, 96.0f}) {
      INFO("error control " << control << ", " << far << " m from the origin");
      Simulation held(bin_graph(nullptr, control, far), 1),
          probed(bin_graph("$TX", control, far), 1), tagged(bin_graph("$ID * 2", control, far), 1),
          speeds(bin_graph("$VX", control, far), 1);
      int substeps = 0;
      for (int f = 0; f < 8; ++f) {
        held.step_frame();
        probed.step_frame();
        tagged.step_frame();
        speeds.step_frame();
        INFO("frame " << f + 1);
        REQUIRE(held.object(0).pts.size() == 1000);
        CHECK(array(held, "P") == array(probed, "P"));
        CHECK(array(held, "v") == array(probed, "v"));
        CHECK(array(held, "P") == array(tagged, "P"));
        CHECK(array(held, "P") == array(speeds, "P"));
        CHECK(array(held, "v") == array(speeds, "v"));
        CHECK(held.object(0).stats.substeps == probed.object(0).stats.substeps);
        CHECK(held.object(0).stats.substeps == speeds.object(0).stats.substeps);
        substeps += held.object(0).stats.substeps;
      }
      REQUIRE(solver_of(speeds));
      CHECK(solver_of(speeds)->motions_on_device() == 0);
      REQUIRE(solver_of(tagged));
      CHECK(solver_of(tagged)->held_starts() == solver_of(held)->held_starts());
      CHECK(tagged.object(0).pts.f_if("probe")[7] ==
            2.0f * float(tagged.object(0).pts.i_if("id")[7]));
      REQUIRE(solver_of(held));
      REQUIRE(solver_of(probed));
      const GrainsSolver& h = *solver_of(held);
      const GrainsSolver& p = *solver_of(probed);
      // every end is held but, with error control, those of the substeps that keep their start
      // velocity (the first of a finer step: no velocity comes back), which also start from the
      // host's: each such substep costs at most its own held start and the next one's. Within a
      // frame the count only doubles, from the 4 substeps to at most max_substeps' 256 (the
      // first frame's coarsening aside, which refines none): at most 6 such substeps a frame
      const int not_held = control ? substeps - int(h.held_ends()) : 0;
      CHECK(h.held_ends() == p.held_ends());
      CHECK(not_held <= 6 * 8);
      if (!control) CHECK(h.held_starts() == size_t(substeps - 8));
      CHECK(h.held_starts() >= size_t(substeps - 8 - 2 * not_held));
      CHECK(p.held_starts() == 0);
      const double saved =
          double(p.device_traffic().received) - double(h.device_traffic().received);
      INFO(substeps << " substeps, " << h.held_starts() << " started there, "
                    << saved / (1000.0 * substeps) << " bytes a grain a substep less");
      CHECK(saved == 24.0 * 1000.0 * double(h.held_starts()));
      // each substep's measure but the frame's last (error control reads none there), and but
      // those after an end not held
      CHECK(h.motions_on_device() + 8 <= size_t(substeps));
      CHECK(h.motions_on_device() + 8 + size_t(not_held) >= (control ? size_t(substeps) : 8));
      if (!control) CHECK(h.motions_on_device() == 0);
      CHECK(p.motions_on_device() == h.motions_on_device());
    }
}
