// The five scaling attributes of the help page that multiply a grains parameter per point
// (repulsionweight, repulsionstiffness, attractionweight, attractionstiffness,
// constraintstiffness): each scales its parameter as the help page says, so a value a on every
// grain gives the run of the parameter times a, and each changes what it should: two grains
// that meet pass through each other, clump or stay joined according to it.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <string>

#include <nlohmann/json.hpp>

#include "tests/support/support.h"

using namespace grains;

namespace {

constexpr double kR = 0.05;  // grain radius (m)

// Two grains of radius kR on the x axis at x = -gap/2 - kR and gap/2 + kR (a surface gap
// `gap`), moving at +speed and -speed along x, every point carrying attribute `attr` = value
// (none when attr is empty); `connect`: joined by an explicit constraint at their birth
// distance. Returns the two x positions after `frames` frames at 24 fps, one substep of 10
// iterations, no gravity and no error control, the grains node's parameters merged from
// `grains`.
std::pair<double, double> meet(double gap, double speed, const std::string& attr, double value,
                               const nlohmann::json& grains, bool connect = false,
                               int frames = 1) {
  const std::string dir = test::temp_dir("scaling");
  std::string ply = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                    "property float z\nproperty float vx\nproperty float vy\nproperty float vz\n"
                    "property float pscale\n";
  if (!attr.empty()) ply += "property float " + attr + "\n";
  ply += "end_header\n";
  const double x = gap / 2 + kR;
  for (int side : {-1, 1}) {
    char row[160];
    std::snprintf(row, sizeof row, "%.9g 1 0 %.9g 0 0 %.9g", side * x, -side * speed, kR);
    ply += row;
    if (!attr.empty()) {
      std::snprintf(row, sizeof row, " %.9g", value);
      ply += row;
    }
    ply += "\n";
  }
  const std::string file = test::write_file(dir, "pair.ply", ply);
  nlohmann::json src = {{"shape", "file"}, {"file", file}, {"separation", 2 * kR}};
  if (connect) src["connect_radius"] = 10;
  nlohmann::json node_params = {{"particle_separation", 2 * kR}, {"constraint_iterations", 10}};
  for (auto& [k, v] : grains.items()) node_params[k] = v;
  nlohmann::json g = {
      {"grains_graph", 1}, {"fps", 24}, {"frames", frames}, {"seed", 1},
      {"nodes",
       {{{"name", "src"}, {"type", "source"}, {"params", src}},
        {{"name", "grains"}, {"type", "grains"}, {"inputs", {"src"}}, {"params", node_params}},
        {{"name", "solver"},
         {"type", "solver"},
         {"inputs", {"grains"}},
         {"params", {{"substeps", 1}, {"error_control", false}}}}}}};
  Simulation sim(test::graph_from(g.dump(), dir + "/pair.json"), 1);
  for (int f = 0; f < frames; ++f) sim.step_frame();
  const float* P = sim.object(0).pts.v3_if("P");
  return {P[0], P[3]};
}

}  // namespace

TEST_CASE("repulsionweight scales internal_collisions_weight: at 0 grains pass through",
          "[grains][attributes]") {
  // Closing at 2 x 0.5 m/s from a 1 cm gap (each grain 2.1 cm a substep, under half a radius,
  // so no pair tunnels through in one step): with collisions they stop in contact; without
  // they cross, each moving 6/24 x 0.5 = 0.125 m in 6 frames
  const auto [a, b] = meet(0.01, 0.5, "", 0, {}, false, 6);
  CHECK(b - a == Approx(2 * kR).margin(1e-4));
  const auto [a0, b0] = meet(0.01, 0.5, "repulsionweight", 0, {}, false, 6);
  CHECK(a0 == Approx(-(0.005 + kR) + 0.125).margin(1e-5));
  CHECK(b0 == Approx(0.005 + kR - 0.125).margin(1e-5));
  // a x the parameter: the attribute 0.5 with weight 1 is the weight 0.5 with no attribute. With
  // one iteration a full weight removes the overlap the frame's motion makes (3.2 cm) at once,
  // a half weight half of it
  const nlohmann::json one = {{"constraint_iterations", 1}};
  const auto full = meet(0.01, 0.5, "", 0, one);
  const auto half_attr = meet(0.01, 0.5, "repulsionweight", 0.5, one);
  const auto half_param =
      meet(0.01, 0.5, "", 0, {{"constraint_iterations", 1}, {"internal_collisions_weight", 0.5}});
  CHECK(half_attr.first == Approx(half_param.first).margin(1e-6));
  CHECK(half_attr.second == Approx(half_param.second).margin(1e-6));
  CHECK(full.second - full.first == Approx(2 * kR).margin(1e-4));
  CHECK(2 * kR - (half_attr.second - half_attr.first) ==
        Approx(0.5 * (2 * 0.5 / 24 - 0.01)).epsilon(0.1));
}

TEST_CASE("repulsionstiffness scales internal_collisions_stiffness: soft contacts overlap",
          "[grains][attributes]") {
  // The stiffness fraction is min(1, k x repulsionstiffness / (substeps x iterations)): the
  // default 1000 is full; 1e-3 of it (k = 1) moves the pair a tenth of its overlap an
  // iteration, so of the 3.2 cm the frame's motion makes 0.9^10 = 35 % (1.1 cm) remains; with
  // full stiffness none does
  const auto [a, b] = meet(0.01, 0.5, "", 0, {});
  const auto [as, bs] = meet(0.01, 0.5, "repulsionstiffness", 1e-3, {});
  CHECK(b - a == Approx(2 * kR).margin(1e-4));
  CHECK(2 * kR - (bs - as) == Approx(0.35 * (2 * 0.5 / 24 - 0.01)).epsilon(0.2));
  const auto param = meet(0.01, 0.5, "", 0, {{"internal_collisions_stiffness", 1.0}});
  CHECK(as == Approx(param.first).margin(1e-6));
  CHECK(bs == Approx(param.second).margin(1e-6));
}

TEST_CASE("attractionweight and attractionstiffness scale clumping", "[grains][attributes]") {
  // Two resting grains 2 mm apart, inside the clumping range (neighbor_query_scale 1.5 x the
  // summed radii): clumping pulls them into contact over a second; with attractionweight or
  // attractionstiffness 0 the gap stays exactly
  const nlohmann::json clump = {{"clumping_weight", 1.0}};
  const auto [a, b] = meet(0.002, 0, "", 0, clump, false, 24);
  CHECK(b - a - 2 * kR < 0.0005);  // closed to under a quarter of the gap
  for (const char* attr : {"attractionweight", "attractionstiffness"}) {
    INFO(attr);
    const auto [a0, b0] = meet(0.002, 0, attr, 0, clump, false, 24);
    CHECK(b0 - a0 == Approx(2 * kR + 0.002).margin(1e-6));
  }
  // a x the parameter
  const auto w_attr = meet(0.002, 0, "attractionweight", 0.3, clump, false, 2);
  const auto w_param = meet(0.002, 0, "", 0, {{"clumping_weight", 0.3}}, false, 2);
  CHECK(w_attr.first == Approx(w_param.first).margin(1e-6));
  const auto k_attr = meet(0.002, 0, "attractionstiffness", 0.01, clump, false, 2);
  const auto k_param = meet(0.002, 0, "", 0, {{"clumping_weight", 1.0}, {"clumping_stiffness", 1.0}},
                            false, 2);
  CHECK(k_attr.first == Approx(k_param.first).margin(1e-6));
  // and it matters: the softer pull has moved them less in those two frames
  const auto k_full = meet(0.002, 0, "", 0, clump, false, 1);
  const auto k_soft = meet(0.002, 0, "attractionstiffness", 1e-3, clump, false, 1);
  // in the first frame the full pull closes the 2 mm gap; 1e-3 of the stiffness (k = 0.1, a
  // hundredth of the gap an iteration) closes 1 - 0.99^10 = 10 % of it
  CHECK(k_full.second - k_full.first - 2 * kR < 1e-6);
  CHECK(k_soft.second - k_soft.first - 2 * kR == Approx(0.002 * std::pow(0.99, 10)).epsilon(0.05));
}

TEST_CASE("constraintstiffness scales explicit_constraints_stiffness: at 0 a joined pair parts",
          "[grains][attributes]") {
  // Joined at their birth distance (1 cm apart) and flying apart at 2 x 1 m/s: the constraint
  // holds them at that distance; with constraintstiffness 0 it does nothing and they part by
  // 2/24 m in the frame
  const auto [a, b] = meet(0.01, -1, "", 0, {}, true);
  CHECK(b - a == Approx(2 * kR + 0.01).margin(1e-4));
  const auto [a0, b0] = meet(0.01, -1, "constraintstiffness", 0, {}, true);
  CHECK(b0 - a0 == Approx(2 * kR + 0.01 + 2.0 / 24).margin(1e-4));
  const auto attr = meet(0.01, -1, "constraintstiffness", 1e-3, {}, true);
  const auto param = meet(0.01, -1, "", 0, {{"explicit_constraints_stiffness", 1.0}}, true);
  CHECK(attr.first == Approx(param.first).margin(1e-6));
  CHECK(attr.second - attr.first > b - a + 0.01);  // soft: stretched by more than a centimetre
}
