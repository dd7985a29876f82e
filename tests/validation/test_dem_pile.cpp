// The heap of the LIGGGHTS reference poured on a rough base (../shared/reference/dem,
// bench/validation/dem_pile.json): 8,000 grains of 1 cm poured at 2,000 a second from 0.35 m
// onto a disc of fixed grains, friction 0.5 (static and kinetic) on grains and floor, measured
// at 4.95 s with the reference's definition (engine/dem_measures.h, `grains heap`: the flank fit
// between 20% and 80% of the peak in 8 sectors). With rotation frozen, as PBD grains are, DEM's
// heap stands at 55.4 deg (sector spread 5.0); frictionless, on the same base, at 27.0 deg
// (spread 8.0): the base's pockets hold the first layer, so even frictionless grains mound
// there (BENCHMARKS.md, against DEM).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <future>

#include "engine/dem_measures.h"
#include "engine/graph.h"
#include "engine/simulation.h"
#include "tests/support/support.h"

using namespace grains;

namespace {

constexpr double kDemAngle = 55.4, kDemSpread = 5.0;                  // frozen rotation
constexpr double kDemCone = 51.5;  // the same heap's cone: atan(peak / foot radius)
constexpr double kDemFrictionless = 27.0, kDemFrictionlessSpread = 8.0;

// seed 0: the graph's own (5)
HeapAngle pour(const std::vector<Override>& overrides, uint64_t seed = 0) {
  register_builtin_nodes();
  Graph g = load_graph(test::source_dir() + "/bench/validation/dem_pile.json", overrides);
  if (seed) g.seed = seed;
  Simulation sim(g, 1);
  for (int f = 0; f < g.frames; ++f) sim.step_frame();
  return heap_angle(sim.object(0).pts, 0.01);
}

}  // namespace

TEST_CASE("DEM pile: the rough-base heap at the defaults, and without friction",
          "[validation][dem]") {
  // The flank of one pour is chaotic: the same pour with its contacts swept in another order
  // stood at 47.6, 51.9 and 53.9 deg (cone 52.4-52.6, peak 0.233-0.234 m), the same order with
  // seed 4 at 56.1 (docs/heap-angle.md, "Blocks of contacts in colours"). The heap with friction
  // is two pours, the graph's seed and seed 4, its angle and peak their means and its sector
  // spread the two spreads' root mean square.
  // The three pours run side by side, each a Simulation of its own on one thread (the same
  // frames as one after another): this is the suite's longest test, and it ends a run alone.
  register_builtin_nodes();  // once, before the threads read the node types
  auto second = std::async(std::launch::async, [] { return pour({}, 4); });
  auto frictionless = std::async(std::launch::async, [] {
    return pour({parse_override("grains.friction_with_particles=0"),
                 parse_override("grains.friction_with_colliders=0")});
  });
  const HeapAngle a = pour({}), b = second.get(), f0 = frictionless.get();
  HeapAngle h = a;
  h.angle_deg = 0.5 * (a.angle_deg + b.angle_deg);
  h.spread_deg = std::sqrt(0.5 * (a.spread_deg * a.spread_deg + b.spread_deg * b.spread_deg));
  h.cone_deg = 0.5 * (a.cone_deg + b.cone_deg);
  h.peak = 0.5 * (a.peak + b.peak);
  h.sectors = std::min(a.sectors, b.sectors);
  INFO("friction 0.5, seed 5: " << a.angle_deg << " deg (sd " << a.spread_deg << "), seed 4: "
                                << b.angle_deg << " deg (sd " << b.spread_deg << ")");
  INFO("friction 0.5: " << h.angle_deg << " deg (sd " << h.spread_deg << " over " << h.sectors
                        << " sectors), cone " << h.cone_deg << ", peak " << h.peak
                        << " m; DEM " << kDemAngle << " (sd " << kDemSpread << ")");
  INFO("friction 0: " << f0.angle_deg << " deg (sd " << f0.spread_deg << "), peak " << f0.peak
                      << " m; DEM " << kDemFrictionless << " (sd " << kDemFrictionlessSpread << ")");
  // every sector has a flank: a heap, not a scatter
  CHECK(h.sectors == 8);
  CHECK(f0.sectors == 8);
  // Without friction the issue asks for no heap; DEM's frozen spheres still mound on the base's
  // pockets, at 27 deg with a sector spread of 8 (its mean over 8 sectors carries 8 / sqrt(8) =
  // 2.8 deg). So no higher than DEM's frictionless heap by more than 5 deg; lower is the issue's
  // way (sleeping grains, a rigid bed under the flow, lower it: 22.1 deg at the defaults; with
  // the Jacobi path 21.6, 23.6 awake; docs/heap-angle.md, "Sleeping by default")
  CHECK(f0.angle_deg <= kDemFrictionless + 5.0);
  // Friction must stand the heap above anything the frictionless DEM reaches (its mean plus its
  // sector spread), and higher than our own frictionless heap by more than both means' noise
  // (sector spreads / sqrt(8), added in quadrature, twice)
  CHECK(h.angle_deg > kDemFrictionless + kDemFrictionlessSpread);
  CHECK(h.angle_deg - f0.angle_deg > 2 * std::hypot(h.spread_deg, f0.spread_deg) / std::sqrt(8.0));
  CHECK(h.peak > f0.peak);
  // The figure: within 5 deg of the frozen DEM (DEM's own sectors spread 5.0). At the
  // defaults, the contacts one at a time with their loads carried: 54.7 and 55.3 deg, mean 55.0
  // (2026-11-29, since pre-stabilization takes the velocity that made an overlap; 47.6 and 56.1
  // before; the Jacobi average of POP Grains, contact_solver jacobi, one pour: 49.0;
  // docs/heap-angle.md)
  CHECK(std::fabs(h.angle_deg - kDemAngle) <= 5.0);
  // each pour's cone, which one pour's chaos moves far less than its flank, within the same 5 deg
  // of DEM's
  CHECK(std::fabs(a.cone_deg - kDemCone) <= 5.0);
  CHECK(std::fabs(b.cone_deg - kDemCone) <= 5.0);
}
