#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>

#include "engine/particles.h"
#include "engine/simulation.h"

using namespace grains;

namespace {

float unit(std::mt19937& rng) { return float(rng() >> 8) * (1.0f / 16777216.0f); }

// n points in a box of side `side`, radius r (or r and 3r alternately when `mixed`); a crowded
// box, so that many pairs overlap, each by an unpredictable amount
ParticleStore cloud(size_t n, float side, float r, bool mixed, uint32_t seed) {
  std::mt19937 rng(seed);
  ParticleStore pts;
  pts.add_points(n);
  float* P = pts.v3("P");
  float* ps = pts.f("pscale");
  for (size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) P[3 * i + a] = side * unit(rng);
    ps[i] = mixed && i % 2 ? 3 * r : r;
  }
  return pts;
}

// the definition, pair by pair in double: overlap / (r_i + r_j) over overlapping pairs
void brute_force(const ParticleStore& pts, double& max, double& mean) {
  const float* P = pts.v3_if("P");
  const float* r = pts.f_if("pscale");
  double sum = 0;
  size_t count = 0;
  max = 0;
  for (size_t i = 0; i < pts.size(); ++i)
    for (size_t j = i + 1; j < pts.size(); ++j) {
      double d2 = 0;
      for (int a = 0; a < 3; ++a) d2 += std::pow(double(P[3 * i + a]) - P[3 * j + a], 2);
      const double rr = double(r[i]) + r[j], pen = (rr - std::sqrt(d2)) / rr;
      if (pen > 0) sum += pen, ++count, max = std::max(max, pen);
    }
  mean = count ? sum / double(count) : 0;
}

}  // namespace

TEST_CASE("frame penetration statistics match the pair-by-pair definition", "[simulation]") {
  for (bool mixed : {false, true}) {
    ParticleStore pts = cloud(3000, 0.5f, 0.02f, mixed, mixed ? 7u : 5u);
    double max = 0, mean = 0;
    brute_force(pts, max, mean);
    FrameStats st;
    measure_frame(pts, st);
    INFO((mixed ? "mixed radii" : "one radius") << ": max " << max << " mean " << mean);
    REQUIRE(mean > 0.1);  // the scene has many overlaps to measure
    // each pair is computed in float (a distance of up to 2 r rounded a few times: relative
    // error ~1e-7 of 2 r, so ~1e-6 of a penetration fraction), summed in double
    CHECK(st.max_penetration == Approx(max).margin(1e-5));
    CHECK(st.mean_penetration == Approx(mean).margin(1e-5));
  }
}
