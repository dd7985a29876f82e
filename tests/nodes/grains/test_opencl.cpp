// The OpenCL backend (a grains node's use_opencl; nodes/grains/opencl/iterations.h) on PoCL's
// CPU device, which scripts/install-deps.sh installs on every machine that runs the tests: the
// same results as the CPU path within float rounding where the motion is smooth, the same
// frames run to run, and a clear refusal where there is no device. Longer runs are checked by
// their physical measures beside the CPU path's tests (stacks, sand_pile, the DEM collapse:
// test names starting "use_opencl:", CTest label opencl).
#include <catch2/catch.hpp>
#include <stdlib.h>

#include <cmath>
#include <filesystem>

#include "tests/support/support.h"

using namespace grains;

namespace {

// sand_pile's first `frames` frames with `sets` and use_opencl as given
std::unique_ptr<Simulation> pour(bool opencl, int frames, std::vector<std::string> sets = {}) {
  register_builtin_nodes();
  sets.push_back(std::string("grains.use_opencl=") + (opencl ? "true" : "false"));
  std::vector<Override> overrides;
  for (const std::string& s : sets) overrides.push_back(parse_override(s));
  Graph g = load_graph(test::source_dir() + "/graphs/sand_pile.json", overrides);
  auto sim = std::make_unique<Simulation>(g, 1);
  for (int f = 0; f < frames; ++f) sim->step_frame();
  return sim;
}

std::vector<float> array(const Simulation& sim, const char* name) {
  const ParticleStore& pts = sim.object(0).pts;
  const float* a = pts.v3_if(name);
  return std::vector<float>(a, a + 3 * pts.size());
}

// runs `args` with the environment variable `var` set to `value` (unset after)
int run_with(const char* var, const std::string& value, const std::string& args,
             const std::string& log) {
  const char* before = getenv(var);
  const std::string saved = before ? before : "";
  setenv(var, value.c_str(), 1);
  const int rc = test::run_grains(args, log);
  if (before) setenv(var, saved.c_str(), 1);
  else unsetenv(var);
  return rc;
}

}  // namespace

TEST_CASE("use_opencl: a frictionless pour agrees with the CPU path within float rounding",
          "[opencl]") {
  // sand_pile without friction, 3 frames (9 substeps of 20 iterations, 149 grains, the stream
  // not yet landing on itself). The backends run the same kernel functions; they may differ in
  // the order of a sum or in where a multiply and an add are fused, a few units in the last
  // place of a coordinate per iteration: 4 x 2^-24 x 0.5 m = 1.2e-7 m. A difference carries
  // into the velocity and on into every later substep, so over S substeps of I iterations it
  // stays under I S^2 / 2 times that: 20 x 40.5 x 1.2e-7 = 9.7e-5 m, 1% of a radius. Past this
  // horizon no such bound holds: grains landing on grains scatter like billiard balls, which
  // doubles a difference at every collision (at frame 4 the two runs are 7 mm apart, at frame 6
  // 8 cm), and a contact's switch between sticking and sliding is a step; the physical measures
  // are compared instead (the other "use_opencl:" tests).
  // The same holds with the neighbour rows or the collider planes rebuilt on the host before
  // every iteration (each iteration then a device call of its own).
  for (const char* extra : {"", "grains.update_neighbors_during_iterations=true",
                            "grains.update_collisions_during_iterations=true"}) {
    INFO("with " << extra);
    std::vector<std::string> frictionless = {"grains.friction_with_particles=0",
                                             "grains.friction_with_colliders=0"};
    if (*extra) frictionless.push_back(extra);
    auto cpu = pour(false, 3, frictionless);
    auto dev = pour(true, 3, frictionless);
    const std::vector<float> a = array(*cpu, "P"), b = array(*dev, "P");
    REQUIRE(a.size() == b.size());
    REQUIRE(a.size() == 3 * 149);
    double worst = 0;
    for (size_t k = 0; k < a.size(); k += 3)
      worst = std::max(worst, std::sqrt(std::pow(a[k] - b[k], 2) + std::pow(a[k + 1] - b[k + 1], 2) +
                                        std::pow(a[k + 2] - b[k + 2], 2)));
    INFO("largest difference " << worst << " m");
    CHECK(worst < 9.7e-5);
  }
}

TEST_CASE("use_opencl: the same graph gives the same frames run to run", "[opencl]") {
  // each work-item writes only its own grain's outputs and sums its contacts in row order:
  // the device's result does not depend on how it schedules them. sand_pile with friction,
  // 6 frames, twice: the same bits.
  auto one = pour(true, 6), two = pour(true, 6);
  CHECK(array(*one, "P") == array(*two, "P"));
  CHECK(array(*one, "v") == array(*two, "v"));
}

TEST_CASE("grains run --opencl runs every grains node on the device", "[cli][opencl]") {
  const std::string dir = test::temp_dir("run_opencl");
  const std::string graph = test::source_dir() + "/graphs/sand_pile.json";
  REQUIRE(test::run_grains("run " + graph + " --frames 2 --opencl --out " + dir + "/dev",
                           dir + "/log.txt") == 0);
  CHECK(std::filesystem::exists(dir + "/dev/frame_0002.ply"));
  // the same as use_opencl in the graph
  auto sim = pour(true, 2);
  CHECK(sim->object(0).pts.size() == 99);
}

TEST_CASE("use_opencl without an OpenCL platform, or with a device that is not there, exits 2",
          "[cli][opencl][bad]") {
  const std::string dir = test::temp_dir("opencl_no_device");
  std::filesystem::create_directories(dir + "/vendors");
  const std::string run = "run " + test::source_dir() + "/graphs/sand_pile.json --frames 1 --opencl --out " +
                          dir + "/o --overwrite";
  const std::string log = dir + "/log.txt";
  // the ICD loader reads its drivers from OCL_ICD_VENDORS: an empty folder is a machine without
  CHECK(run_with("OCL_ICD_VENDORS", dir + "/vendors", run, log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("/nodes/2/params/use_opencl: no OpenCL platform found"));
  CHECK(run_with("GRAINS_OPENCL_DEVICE", "0:7", run, log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("GRAINS_OPENCL_DEVICE: no device 0:7"));
  CHECK(run_with("GRAINS_OPENCL_DEVICE", "any", run, log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("GRAINS_OPENCL_DEVICE: 'any' is not PLATFORM:DEVICE"));
}
