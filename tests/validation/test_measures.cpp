// The measurements and fits behind `grains-lab laws` (lab/validation.h), on synthetic particles whose
// answer is known, so that the law tests beside this file judge the solver, not the ruler.
#include <catch2/catch.hpp>
#include <cmath>

#include "engine/dem_measures.h"
#include "lab/validation.h"

using namespace grains;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Points at the given positions, pscale r, mass 1 (or masses[k] when given).
ParticleStore points(const std::vector<Vec3>& at, float r, const std::vector<float>& masses = {}) {
  ParticleStore s;
  s.add_points(at.size());
  float* P = s.v3("P");
  float* ps = s.f("pscale");
  float* mass = s.f("mass");
  for (size_t k = 0; k < at.size(); ++k) {
    store3(P, k, at[k]);
    ps[k] = r;
    mass[k] = masses.empty() ? 1.0f : masses[k];
  }
  return s;
}

// The validation scenes' columns: lattice cells d wide, centres (i + 1/2) d, kept within R0.
std::vector<Vec3> lattice_column(int radius_cells, int layers, double d) {
  std::vector<Vec3> out;
  double r0 = radius_cells * d;
  for (int j = 0; j < layers; ++j)
    for (int i = -radius_cells; i < radius_cells; ++i)
      for (int k = -radius_cells; k < radius_cells; ++k) {
        double x = (i + 0.5) * d, z = (k + 0.5) * d;
        if (x * x + z * z <= r0 * r0) out.push_back(Vec3{float(x), float((j + 0.5) * d), float(z)});
      }
  return out;
}

}  // namespace

TEST_CASE("fit_line and fit_power recover exact laws", "[validation][measures]") {
  std::vector<double> x = {1, 2, 3, 5, 8}, y, p;
  for (double v : x) y.push_back(3 - 0.5 * v), p.push_back(0.7 * std::pow(v, 2.5));
  LineFit l = fit_line(x, y);
  CHECK(l.slope == Approx(-0.5));
  CHECK(l.intercept == Approx(3));
  CHECK(l.r2 == Approx(1));
  PowerFit f = fit_power(x, p);
  CHECK(f.exponent == Approx(2.5));
  CHECK(f.prefactor == Approx(0.7));
}

TEST_CASE("deposit_radius of lattice columns and of a thin disc", "[validation][measures]") {
  // A column of cells d wide covers the disc of R0; the half-monolayer edge, interpolated between
  // rings d wide, lies within [-d/4, +d/2] of R0 for one to forty layers (one layer: cover ~0.8
  // falls to 0 over a ring, so the crossing sits inside the last ring; many layers push the
  // crossing towards the first empty ring's centre, R0 + d/2).
  double d = 0.02;
  for (int cells : {6, 10})
    for (int layers : {1, 5, 40}) {
      INFO(cells << " cells, " << layers << " layers");
      double r = deposit_radius(points(lattice_column(cells, layers, d), d / 2), 0, 0, d);
      CHECK(r >= cells * d - d / 4);
      CHECK(r <= cells * d + d / 2 + 1e-9);
    }
  // grains thrown beyond a deposit do not count: a ring of 20 loose grains at 2 R0
  std::vector<Vec3> pts = lattice_column(10, 3, d);
  for (int k = 0; k < 20; ++k)
    pts.push_back(Vec3{float(0.4 * std::cos(k * 0.314)), 0.01f, float(0.4 * std::sin(k * 0.314))});
  CHECK(deposit_radius(points(pts, d / 2), 0, 0, d) < 10 * d + d / 2 + 1e-9);
}

// A cone of grains on a lattice d wide whose surface is h(r) = H - r t, every column of cells
// filled up to the surface, on a fixed bed (mass 0) one cell thick.
static void lattice_cone(double d, double H, double t, std::vector<Vec3>& at, std::vector<float>& mass) {
  for (int i = -30; i < 30; ++i)
    for (int k = -30; k < 30; ++k) {
      double x = (i + 0.5) * d, z = (k + 0.5) * d, r = std::hypot(x, z);
      at.push_back(Vec3{float(x), float(-d / 2), float(z)});  // the fixed bed
      mass.push_back(0);
      for (int j = 0; (j + 1) * d <= H - r * t; ++j) {
        at.push_back(Vec3{float(x), float((j + 0.5) * d), float(z)});
        mass.push_back(1);
      }
    }
}

TEST_CASE("pile_slope of a lattice cone is its angle", "[validation][measures]") {
  // A cone of grains on a lattice d wide whose surface is h(r) = H - r tan(theta): every column
  // of cells is filled up to the surface. The highest top in a ring of width d follows the
  // surface to within one cell (d) over the flank's 0.2 R..0.8 R, a span of 0.6 R = 12 d here,
  // so the fitted slope is within about d / (0.6 R) of tan(theta): 5 degrees at 30 degrees. A
  // fixed bed (mass 0) under it and grains above y_max are ignored.
  double d = 0.02;
  for (double theta : {20.0, 30.0, 40.0}) {
    INFO("theta " << theta);
    double t = std::tan(theta * kPi / 180), R = 20 * d, H = R * t;
    std::vector<Vec3> at;
    std::vector<float> mass;
    lattice_cone(d, H, t, at, mass);
    at.push_back(Vec3{0.1f, 2.0f, 0.1f});  // a stray grain above y_max
    mass.push_back(1);
    ParticleStore s = points(at, float(d / 2), mass);
    PileSlope p = pile_slope(s, 0, 0, d, 1.0);
    CHECK(p.sectors == 8);
    CHECK(p.angle_deg == Approx(theta).margin(5));
    CHECK(p.height <= H + d);
  }
}

TEST_CASE("fit_beverloo recovers n, k and C from exact Beverloo rates", "[validation][measures]") {
  double d = 0.02, nb = 6e4, c = 0.6;
  std::vector<SiloResult> runs;
  for (int od : {4, 5, 6, 7, 8}) {
    SiloResult r;
    r.orifice = od * d;
    r.number_density = nb;
    r.rate = c * nb * std::sqrt(9.81) * std::pow(r.orifice - 1.4 * d, 2.5);
    runs.push_back(r);
  }
  BeverlooFit f = fit_beverloo(runs, d);
  CHECK(f.exponent_k14 == Approx(2.5).margin(1e-6));
  CHECK(f.r2_k14 == Approx(1));
  CHECK(f.k_linear == Approx(1.4).margin(1e-6));
  CHECK(f.r2_linear == Approx(1));
  CHECK(f.k_free == Approx(1.4).margin(0.01));
  CHECK(f.exponent_free == Approx(2.5).margin(0.02));
  CHECK(f.c == Approx(c));
  CHECK(f.c_spread == Approx(0).margin(1e-9));
}

TEST_CASE("heap_angle of a lattice cone is its angle, and a flat layer has none",
          "[validation][measures]") {
  // The DEM reference's definition (engine/dem_measures.h) on the cone above: rings d wide between
  // 20% and 80% of the peak follow the surface to within one cell, over 0.6 of the flank's
  // 20 d: within about d / (0.6 R), 5 degrees at 30. A fixed bed (mass 0) is not the heap. A
  // layer two grains thick has no ring between 20% and 80% of its peak inside its foot: 0.
  double d = 0.02;
  for (double theta : {20.0, 30.0, 40.0}) {
    INFO("theta " << theta);
    double t = std::tan(theta * kPi / 180), R = 20 * d, H = R * t;
    std::vector<Vec3> at;
    std::vector<float> mass;
    lattice_cone(d, H, t, at, mass);
    HeapAngle h = heap_angle(points(at, float(d / 2), mass), d);
    CHECK(h.sectors == 8);
    CHECK(h.angle_deg == Approx(theta).margin(5));
    CHECK(h.peak <= H + d);
  }
  std::vector<Vec3> layer;
  for (int i = -20; i < 20; ++i)
    for (int k = -20; k < 20; ++k)
      for (int j = 0; j < 2; ++j)
        layer.push_back(Vec3{float((i + 0.5) * d), float((j + 0.5) * d), float((k + 0.5) * d)});
  HeapAngle flat = heap_angle(points(layer, float(d / 2), std::vector<float>(layer.size(), 1)), d);
  CHECK(flat.angle_deg == 0);
}

TEST_CASE("collapse_metric finds the deposit's front and height as the DEM script does",
          "[validation][measures]") {
  // A column L0 = 10 d long, H0 = 20 d high, 4 d wide, against x = 0; the deposit is a block
  // 15 d long, 2 d high, with 3 strays farther out. The front is the first slice of width d
  // holding fewer than half a monolayer (2 grains of 4 across): at 15 d, run-out 0.5, H / L0 0.2.
  double d = 0.01;
  std::vector<Vec3> column, deposit;
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 20; ++j)
      for (int k = 0; k < 4; ++k)
        column.push_back(Vec3{float((i + 0.5) * d), float((j + 0.5) * d), float((k + 0.5) * d)});
  for (int i = 0; i < 15; ++i)
    for (int j = 0; j < 2; ++j)
      for (int k = 0; k < 4; ++k)
        deposit.push_back(Vec3{float((i + 0.5) * d), float((j + 0.5) * d), float((k + 0.5) * d)});
  for (int s = 0; s < 3; ++s)
    deposit.push_back(Vec3{float((18.5 + 2 * s) * d), float(d / 2), float(d / 2)});
  const float r = float(d / 2);
  CollapseMetric m = collapse_metric(points(column, r, std::vector<float>(column.size(), 1)),
                                     points(deposit, r, std::vector<float>(deposit.size(), 1)), d);
  CHECK(m.L0 == Approx(10 * d));
  CHECK(m.H0 == Approx(20 * d));
  CHECK(m.L == Approx(15 * d));
  CHECK(m.runout == Approx(0.5));
  CHECK(m.height == Approx(0.2));
  CHECK(m.beyond == 3);
}
