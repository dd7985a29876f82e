// A grains node's substep end held on the OpenCL device between the substeps of a frame
// (GrainsData::may_hold_end, the store's held attributes in engine/particles.h): the positions
// and velocities come back once a frame, or when another node reads them, and the frames are
// the same bits as when they come back every substep.
#include <catch2/catch.hpp>
#include <string>
#include <vector>

#include "nodes/grains/grains_node.h"
#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/bin_scene.h"
#include "tests/support/support.h"

using namespace grains;

namespace {

// The bin (bin_scene.h) with its floor at height 0 and its centre `far` from the world's origin
// along x and z, 8 frames, and no sleeping (whose test reads the positions every substep). With
// `probe` an attribute node after the grains node sets the attribute "probe" to that expression
// each substep: "$TX" reads every grain's position, which brings them back each time.
Graph bin_graph(const char* probe, bool error_control, float far) {
  test::BinScene b;
  b.far = far;
  b.sleeping = false;
  b.probe = probe;
  b.error_control = error_control;
  b.file = "hold.json";
  return test::bin_graph(b);
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
      REQUIRE(test::bin_solver(speeds));
      CHECK(test::bin_solver(speeds)->motions_on_device() == 0);
      REQUIRE(test::bin_solver(tagged));
      CHECK(test::bin_solver(tagged)->held_starts() == test::bin_solver(held)->held_starts());
      CHECK(tagged.object(0).pts.f_if("probe")[7] ==
            2.0f * float(tagged.object(0).pts.i_if("id")[7]));
      REQUIRE(test::bin_solver(held));
      REQUIRE(test::bin_solver(probed));
      const GrainsSolver& h = *test::bin_solver(held);
      const GrainsSolver& p = *test::bin_solver(probed);
      // every end is held, with error control those of the substeps that keep their start
      // velocity too (the first of a finer step: the device's end writes it), and every start
      // but a frame's first, theirs too (the device holds the velocity they keep)
      CHECK(h.held_ends() == size_t(substeps));
      CHECK(h.held_ends() == p.held_ends());
      CHECK(h.held_starts() == size_t(substeps - 8));
      CHECK(p.held_starts() == 0);
      const double saved =
          double(p.device_traffic().received) - double(h.device_traffic().received);
      INFO(substeps << " substeps, " << h.held_starts() << " started there, "
                    << saved / (1000.0 * substeps) << " bytes a grain a substep less");
      CHECK(saved == 24.0 * 1000.0 * double(h.held_starts()));
      // with error control, each substep's measure but the frame's last (error control reads
      // none there): every end is held
      CHECK(h.motions_on_device() == (control ? size_t(substeps - 8) : 0));
      CHECK(p.motions_on_device() == h.motions_on_device());
    }
}
