// The a = 2 planar column collapse of the LIGGGHTS reference (../shared/reference/dem,
// bench/validation/dem_collapse.json): 4,854 grains of 1 cm from the DEM's own settled packing,
// between side walls 10 d apart, friction 0.5 (static and kinetic) on grains and walls. With
// rotation frozen, as PBD grains are, DEM keeps the column's full height (H / L0 = 2.00) and runs
// its toe out 0.86 L0 in 0.95 s.
#include <catch2/catch.hpp>

#include "app/dem_measures.h"
#include "app/validation.h"
#include "engine/geometry_io.h"
#include "tests/support/support.h"

using namespace grains;

TEST_CASE("DEM collapse: the a = 2 column keeps its height and does not flow like a liquid",
          "[validation][dem]") {
  // At 128 substeps x 20 iterations (error control off, so the setting is the test's) the
  // column must keep H / L0 within 2% of DEM's 2.00 (DEM's own spread: dt halved or doubled,
  // another packing, +-2%), and its toe may not run out farther than DEM's 0.86 plus 10%: the
  // default PBD material had crushed it to a layer (H / L0 0.07) and run it out 3.1 L0, and 2 x 40
  // ran it out 7.2 L0. Converged rigid grains with Coulomb friction keep the toe shorter than
  // DEM's soft contacts do (0.20 measured; VALIDATION.md, BENCHMARKS.md), which is reported, not
  // asserted.
  register_builtin_nodes();
  const std::string scene = test::source_dir() + "/bench/validation/dem_collapse.json";
  Graph g = load_graph(
      scene, {parse_override("solver.substeps=128"), parse_override("solver.error_control=0"),
              parse_override("grains.constraint_iterations=20")});
  Simulation sim(g, 1);
  for (int f = 0; f < g.frames; ++f) sim.step_frame();
  const ParticleStore initial =
      read_ply(test::source_dir() + "/bench/validation/data/dem_column.ply");
  REQUIRE(initial.size() == 4854);
  const ParticleStore& fin = sim.object(0).pts;
  REQUIRE(fin.size() == 4854);
  CollapseMetric m = collapse_metric(initial, fin, 0.01);
  INFO("run-out " << m.runout << " (DEM 0.86), H / L0 " << m.height << " (DEM 2.00), " << m.beyond
                  << " grains past the front");
  CHECK(std::fabs(m.height - 2.00) <= 0.02 * 2.00);
  CHECK(m.runout <= 0.86 * 1.1);
  CHECK(m.runout >= 0);
}
