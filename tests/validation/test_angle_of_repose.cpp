// Angle of repose of a poured pile against DEM of spheres (Zhou et al. 2001, PRE 64, 021301;
// pbd_research.md s5), at the quick plan of `grains-lab laws` (bench/validation/README.md): the
// node defaults, fixed-funnel method on a rough bed of fixed grains.
#include <catch2/catch.hpp>
#include <cmath>

#include "lab/validation.h"
#include "tests/support/support.h"

using namespace grains;

TEST_CASE("angle of repose: rises with friction, in the DEM range for spheres",
          "[validation][repose]") {
  register_builtin_nodes();
  ValidationPlan plan = validation_plan(true);
  const LawSettings s = law_settings(plan, plan.solver_settings.front());
  std::string scene = test::source_dir() + "/bench/validation/angle_of_repose.json";
  std::vector<ReposeResult> runs;
  // one thread: CTest runs two tests at once on a 2-core machine, and two 2-thread
  // OpenMP teams on two cores stall each other at every barrier
  for (double mu : plan.frictions) runs.push_back(run_repose(scene, mu, plan.pile, s, 1));

  for (const auto& r : runs) {
    INFO("friction " << r.friction << ": " << r.slope.angle_deg << " deg (sector spread "
                     << r.slope.spread_deg << ", 1 s earlier " << r.slope_earlier.angle_deg << "), "
                     << r.grains - r.left_in_hopper << " grains poured");
    // a pile formed: most of the hopper emptied and every sector's flank could be fitted
    CHECK(r.left_in_hopper < r.grains / 2);
    CHECK(r.slope.sectors == 8);
    // a static pile keeps its angle: over the last second it changes by less than the mean's
    // noise over 8 sectors (a few degrees; below); 2 degrees
    CHECK(std::fabs(r.slope.angle_deg - r.slope_earlier.angle_deg) <= 2.0);
  }
  // Rises with friction (Zhou 2001: monotone in the sliding friction). The mean over 8 sectors
  // carries sector spread / sqrt(8), a few degrees. Every step must rise (monotone), and the
  // whole span of frictions, a factor of 5 or more, must gain more than twice that noise.
  for (size_t k = 1; k < runs.size(); ++k) {
    const auto& a = runs[k - 1];
    const auto& b = runs[k];
    INFO("friction " << a.friction << " -> " << b.friction << ": " << a.slope.angle_deg << " -> "
                     << b.slope.angle_deg << " deg");
    CHECK(b.slope.angle_deg > a.slope.angle_deg);
  }
  {
    const auto& a = runs.front();
    const auto& b = runs.back();
    double noise = std::hypot(a.slope.spread_deg, b.slope.spread_deg) / std::sqrt(8.0);
    INFO("friction " << a.friction << " -> " << b.friction << ": " << a.slope.angle_deg << " -> "
                     << b.slope.angle_deg << " deg, noise " << noise);
    CHECK(b.slope.angle_deg - a.slope.angle_deg > 2 * noise);
  }
  // At friction 0.5, a sphere DEM value of the sliding coefficient, the angle lies in the range
  // DEM reports for spheres at mu = 0.4-0.5 with rolling friction 0.02-0.2: 18.7-47 deg. Our
  // grains do not rotate, so they sit towards the rolling-resistant end; the band's own ends
  // are the tolerance.
  for (const auto& r : runs)
    if (std::fabs(r.friction - 0.5) < 1e-9) {
      INFO("friction 0.5: " << r.slope.angle_deg << " deg");
      CHECK(r.slope.angle_deg >= kReposeDemLow);
      CHECK(r.slope.angle_deg <= kReposeDemHigh);
    }
}
