#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "nodes/grains/kernels/prelude.h"

void load_block_portable(const float* a, const gr_uint* j, float* x, float* y, float* z);
void add_block_portable(gr_uint* sum, const float* add, float s);

TEST_CASE("the contact loop's block load reads the same positions on every path", "[grains]") {
  // n grains in 3 n + 1 floats (the solver's iterates), every float distinct, so a lane that
  // read the wrong grain or the wrong coordinate cannot match; blocks include grain 0, the last
  // grain (whose load reads the padding float) and repeated grains (a row's tail)
  const int n = 1000;
  std::vector<float> a(3 * n + 1);
  for (size_t k = 0; k < a.size(); ++k) a[k] = 0.5f + float(k);
  std::mt19937 rng(3);
  for (int block = 0; block < 200; ++block) {
    gr_uint j[8];
    for (int l = 0; l < 8; ++l) j[l] = gr_uint(rng() % n);
    if (block == 0) j[0] = 0, j[7] = n - 1;
    if (block == 1) for (int l = 3; l < 8; ++l) j[l] = n - 1;
    float x[8], y[8], z[8], px[8], py[8], pz[8];
    gr_load_block(a.data(), j, x, y, z);
    load_block_portable(a.data(), j, px, py, pz);
    for (int l = 0; l < 8; ++l) {
      INFO("block " << block << " lane " << l << " grain " << j[l]);
      CHECK(x[l] == a[3 * j[l]]);
      CHECK(y[l] == a[3 * j[l] + 1]);
      CHECK(z[l] == a[3 * j[l] + 2]);
      CHECK(std::memcmp(&x[l], &px[l], sizeof(float)) == 0);
      CHECK(std::memcmp(&y[l], &py[l], sizeof(float)) == 0);
      CHECK(std::memcmp(&z[l], &pz[l], sizeof(float)) == 0);
    }
  }
}

TEST_CASE("the friction sums' block update adds the same bits on every path", "[grains]") {
  // sums stored as float bits; distinct values per lane, so a lane moved or dropped cannot match.
  // With FMA the vector update is one rounding, add * s + sum, exactly. The portable loop is
  // `sum + add * s`: fused too where the compiler contracts it (GCC at -O2 and above, so in the
  // release build the two paths give the same bits), else a product and a sum each rounded once
  // (the -O1 sanitizer build), at most one ulp from the fused value. GRAINS_RELEASE_BUILD: the
  // build type is Release (CMakeLists.txt).
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1e-3f);
  for (int block = 0; block < 200; ++block) {
    gr_uint sum[8], ref[8], before[8];
    float add[8];
    const float s = 1.0f / float(1 + block % 31);
    for (int l = 0; l < 8; ++l) {
      sum[l] = ref[l] = before[l] = gr_as_uint(block == 0 ? 0.0f : u(rng));
      add[l] = l == 3 ? 0.0f : u(rng);
    }
    gr_add_block(sum, add, s);
    add_block_portable(ref, add, s);
    for (int l = 0; l < 8; ++l) {
      INFO("block " << block << " lane " << l);
      const float fused = std::fma(add[l], s, gr_as_float(before[l]));
      const float one_ulp = std::numeric_limits<float>::epsilon() * std::fabs(fused);
#if defined(__FMA__)
      CHECK(gr_as_float(sum[l]) == fused);
#endif
#if defined(GRAINS_RELEASE_BUILD) || !defined(__FMA__)
      CHECK(sum[l] == ref[l]);  // the same bits on both paths
#endif
      CHECK(std::fabs(gr_as_float(ref[l]) - fused) <= one_ulp);
    }
  }
}

TEST_CASE("the contact loop's lane sums add the lanes in the portable loop's order", "[grains]") {
  // The portable loop adds lane 0, then lane 1, ... to zero; float addition is not associative,
  // so the transpose path must keep that order to give the same frames. Lanes of magnitudes
  // from 1e-4 to 1e4 and both signs make another order round differently (a pairwise order differs
  // from the sequential sum in 370 of these 800 sums).
#ifdef GR_HAVE_SUM_LANES
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> mant(-1.0f, 1.0f);
  std::uniform_int_distribution<int> expo(-4, 4);
  int reordered_differs = 0;
  for (int block = 0; block < 200; ++block) {
    float v[4][8];
    for (auto& lanes : v)
      for (float& x : lanes) x = mant(rng) * std::pow(10.0f, float(expo(rng)));
    float out[4];
    gr_sum_lanes(v[0], v[1], v[2], v[3], out);
    for (int c = 0; c < 4; ++c) {
      float seq = 0.0f, pairwise = 0.0f;
      for (int l = 0; l < 8; ++l) seq += v[c][l];
      pairwise = ((v[c][0] + v[c][1]) + (v[c][2] + v[c][3])) + ((v[c][4] + v[c][5]) + (v[c][6] + v[c][7]));
      if (pairwise != seq) ++reordered_differs;
      INFO("block " << block << " component " << c);
      CHECK(std::memcmp(&out[c], &seq, sizeof(float)) == 0);
    }
  }
  // the test can tell orders apart
  CHECK(reordered_differs > 100);
#else
  SUCCEED("no vector lane sum in this build: the portable loop is the only path");
#endif
}
