// kill: the region shapes, cylinder included (bench/validation carves its columns with it).
#include <catch2/catch.hpp>
#include <cmath>

#include "engine/simulation.h"
#include "tests/support/support.h"

using namespace grains;

namespace {

// A 20 x 20 x 20 grid of spacing 0.1 centred at the origin (coordinates +-0.05 ... +-0.95), then
// one kill node with `params`.
ParticleStore after_kill(const std::string& params) {
  std::string g = R"({"grains_graph": 1, "frames": 1, "nodes": [
      {"name": "src", "type": "source", "params": {"shape": "box", "size": [2.05, 2.05, 2.05], "separation": 0.1}},
      {"name": "k", "type": "kill", "inputs": ["src"], "params": )" +
                  params + R"(},
      {"name": "s", "type": "solver", "inputs": ["k"]}]})";
  Simulation sim(test::graph_from(g));
  sim.step_frame();
  return sim.object(0).pts;
}

}  // namespace

TEST_CASE("kill cylinder: a vertical cylinder of radius and height size.y", "[nodes][kill]") {
  // Keep the inside of a cylinder of radius 0.45 and height 1 (invert): every survivor is in it,
  // and the count is the grid's: per layer the lattice points (a/20, b/20), a and b odd, with
  // a^2 + b^2 <= 9^2 (none lies on the circle: a sum of two odd squares is 2 mod 4), times the
  // 10 layers |y| <= 0.5.
  ParticleStore pts = after_kill(
      R"({"shape": "cylinder", "center": [0, 0, 0], "radius": 0.45, "size": [0, 1.0, 0], "invert": true})");
  int per_layer = 0;
  for (int a = -19; a <= 19; a += 2)
    for (int b = -19; b <= 19; b += 2)
      if (a * a + b * b <= 81) ++per_layer;
  CHECK(pts.size() == static_cast<size_t>(per_layer * 10));
  const float* P = pts.v3_if("P");
  for (size_t k = 0; k < pts.size(); ++k) {
    CHECK(std::hypot(P[3 * k], P[3 * k + 2]) <= 0.45f + 1e-5f);
    CHECK(std::fabs(P[3 * k + 1]) <= 0.5f + 1e-5f);
  }
  // without invert the same cylinder is removed and everything else stays
  ParticleStore rest = after_kill(
      R"({"shape": "cylinder", "center": [0, 0, 0], "radius": 0.45, "size": [0, 1.0, 0]})");
  CHECK(rest.size() == 20u * 20u * 20u - static_cast<size_t>(per_layer * 10));
}
