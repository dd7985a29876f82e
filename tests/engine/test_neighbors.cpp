#include <catch2/catch.hpp>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "engine/neighbors.h"
#include "tests/support/cloud.h"

using namespace grains;
using test::Cloud;
using test::unit;

namespace {

// n points uniform in a cube of side `side`, one radius.
Cloud uniform_cloud(size_t n, float side, float radius, uint32_t seed) {
  std::mt19937 rng(seed);
  Cloud c;
  for (size_t i = 0; i < n; ++i) {
    float x = side * unit(rng), y = side * unit(rng), z = side * unit(rng);
    c.add(x, y, z, radius);
  }
  return c;
}

// n points uniform in a cube, radii log-uniform in [rmin, rmax].
Cloud mixed_cloud(size_t n, float side, float rmin, float rmax, uint32_t seed) {
  std::mt19937 rng(seed);
  Cloud c;
  const float ratio = std::log(rmax / rmin);
  for (size_t i = 0; i < n; ++i) {
    float x = side * unit(rng), y = side * unit(rng), z = side * unit(rng);
    c.add(x, y, z, rmin * std::exp(ratio * unit(rng)));
  }
  return c;
}

NeighborList grid(const Cloud& c, const NeighborQuery& q) {
  NeighborSearch s;
  NeighborList out;
  s.find(c.P.data(), c.r.data(), c.size(), q, out);
  return out;
}

NeighborList brute(const Cloud& c, const NeighborQuery& q) {
  NeighborList out;
  find_neighbors_brute(c.P.data(), c.r.data(), c.size(), q, out);
  return out;
}

// The lists by definition, written independently of the library's selection: every pair
// within qs * (ri + rj) (squared distance of the float differences, in double), ordered by
// (that distance as a float, index), cut to max_neighbors.
NeighborList by_definition(const Cloud& c, const NeighborQuery& q) {
  const size_t n = c.size();
  NeighborList out;
  out.offsets.assign(n + 1, 0);
  for (size_t i = 0; i < n; ++i) {
    std::vector<std::pair<float, uint32_t>> cand;
    for (size_t j = 0; j < n; ++j) {
      if (j == i) continue;
      const double dx = c.P[3 * i] - c.P[3 * j], dy = c.P[3 * i + 1] - c.P[3 * j + 1],
                   dz = c.P[3 * i + 2] - c.P[3 * j + 2];
      const double d2 = dx * dx + dy * dy + dz * dz;
      const float t = q.query_scale * (c.r[i] + c.r[j]);
      if (t > 0.0f && d2 < double(t) * double(t))
        cand.push_back({static_cast<float>(d2), static_cast<uint32_t>(j)});
    }
    std::sort(cand.begin(), cand.end());
    if (q.max_neighbors > 0 && cand.size() > size_t(q.max_neighbors))
      cand.resize(q.max_neighbors);
    for (const auto& e : cand) out.indices.push_back(e.second);
    out.offsets[i + 1] = static_cast<uint32_t>(out.indices.size());
  }
  return out;
}

NeighborQuery query(float scale, int max_neighbors, bool uniform, int threads = 0) {
  NeighborQuery q;
  q.query_scale = scale;
  q.max_neighbors = max_neighbors;
  q.uniform_radius = uniform;
  q.threads = threads;
  return q;
}

void require_same(const NeighborList& a, const NeighborList& b) {
  REQUIRE(a.offsets.size() == b.offsets.size());
  REQUIRE(a.offsets == b.offsets);
  REQUIRE(a.indices == b.indices);
}

double dist(const Cloud& c, size_t i, size_t j) {
  double d = 0;
  for (int a = 0; a < 3; ++a) {
    double v = double(c.P[3 * i + a]) - double(c.P[3 * j + a]);
    d += v * v;
  }
  return std::sqrt(d);
}

// The rules every list must follow, checked independently of brute force.
void check_rules(const Cloud& c, const NeighborList& nl, const NeighborQuery& q) {
  const size_t n = c.size();
  REQUIRE(nl.offsets.size() == n + 1);
  REQUIRE(nl.offsets[0] == 0);
  REQUIRE(nl.offsets[n] == nl.indices.size());
  for (size_t i = 0; i < n; ++i) {
    REQUIRE(nl.offsets[i] <= nl.offsets[i + 1]);
    if (q.max_neighbors > 0) REQUIRE(nl.count(i) <= size_t(q.max_neighbors));
    double last = -1;
    for (uint32_t e = nl.offsets[i]; e < nl.offsets[i + 1]; ++e) {
      const uint32_t j = nl.indices[e];
      REQUIRE(j < n);
      REQUIRE(j != i);
      const double d = dist(c, i, j);
      REQUIRE(d < q.query_scale * (double(c.r[i]) + c.r[j]) * (1 + 1e-6));
      REQUIRE(d >= last * (1 - 1e-6));
      last = d;
    }
  }
}

size_t total_pairs(const NeighborList& nl) { return nl.indices.size(); }

}  // namespace

TEST_CASE("uniform grid matches brute force on random clouds", "[neighbors]") {
  for (uint32_t seed : {1u, 2u, 3u}) {
    Cloud c = uniform_cloud(2000, 1.0f, 0.04f, seed);
    for (float scale : {1.0f, 1.5f, 2.5f})
      for (int cap : {0, -1, 4, 32}) {
        INFO("seed " << seed << " scale " << scale << " cap " << cap);
        NeighborQuery q = query(scale, cap, true);
        NeighborList g = grid(c, q), b = brute(c, q);
        require_same(g, b);
        if (seed == 1) require_same(g, by_definition(c, q));  // the nearest kept, by any sort
        check_rules(c, g, q);
        REQUIRE(total_pairs(g) > 0);
      }
  }
}

TEST_CASE("uncapped lists are symmetric", "[neighbors]") {
  Cloud c = mixed_cloud(1500, 1.0f, 0.005f, 0.05f, 11);
  NeighborList g = grid(c, query(1.5f, 0, false));
  for (size_t i = 0; i < c.size(); ++i)
    for (uint32_t e = g.offsets[i]; e < g.offsets[i + 1]; ++e) {
      const uint32_t j = g.indices[e];
      bool back = false;
      for (uint32_t f = g.offsets[j]; f < g.offsets[j + 1]; ++f) back |= g.indices[f] == i;
      REQUIRE(back);
    }
}

TEST_CASE("multi-level grid matches brute force with 10x radius ratios", "[neighbors]") {
  SECTION("log-uniform radii") {
    for (uint32_t seed : {4u, 5u}) {
      Cloud c = mixed_cloud(2000, 1.0f, 0.005f, 0.05f, seed);
      for (float scale : {1.0f, 1.5f, 3.0f})
        for (int cap : {0, 6, 32}) {
          INFO("seed " << seed << " scale " << scale << " cap " << cap);
          NeighborQuery q = query(scale, cap, false);
          NeighborList g = grid(c, q), b = brute(c, q);
          require_same(g, b);
          check_rules(c, g, q);
        }
    }
  }
  SECTION("two populations: many small grains around a few large ones") {
    std::mt19937 rng(99);
    Cloud c;
    for (int i = 0; i < 1900; ++i) c.add(unit(rng), unit(rng), unit(rng), 0.01f);
    for (int i = 0; i < 100; ++i) c.add(unit(rng), unit(rng), unit(rng), 0.1f + 0.05f * unit(rng));
    for (int cap : {0, 16}) {
      NeighborQuery q = query(1.5f, cap, false);
      require_same(grid(c, q), brute(c, q));
    }
  }
  SECTION("radii spanning many powers of two, including zero") {
    std::mt19937 rng(7);
    Cloud c;
    for (int i = 0; i < 1500; ++i)
      c.add(unit(rng), unit(rng), unit(rng), i % 50 == 0 ? 0.0f : 0.001f * std::pow(2.0f, 7.0f * unit(rng)));
    NeighborQuery q = query(1.5f, 0, false);
    require_same(grid(c, q), brute(c, q));
  }
}

TEST_CASE("multi-level grid stays exact with 100x radius ratios and unusual scales", "[neighbors]") {
  SECTION("radii from 0.0005 to 0.05") {
    Cloud c = mixed_cloud(2000, 0.5f, 0.0005f, 0.05f, 8);
    for (int cap : {0, 4, 32}) {
      NeighborQuery q = query(1.5f, cap, false);
      NeighborList g = grid(c, q);
      require_same(g, brute(c, q));
      check_rules(c, g, q);
    }
  }
  SECTION("a cloud far from the origin") {
    Cloud c = mixed_cloud(2000, 1.0f, 0.01f, 0.08f, 9);
    for (size_t i = 0; i < c.size(); ++i) c.P[3 * i] += 1.0e5f, c.P[3 * i + 1] -= 3.0e4f;
    for (bool uniform : {true, false}) {
      NeighborQuery q = query(1.5f, 16, uniform);
      require_same(grid(c, q), brute(c, q));
    }
  }
  SECTION("tiny and huge length scales") {
    for (float scale : {1.0e-18f, 1.0e15f}) {
      Cloud c = mixed_cloud(1000, 1.0f, 0.01f, 0.1f, 10);
      for (float& v : c.P) v *= scale;
      for (float& v : c.r) v *= scale;
      for (bool uniform : {true, false}) {
        INFO("scale " << scale << " uniform " << uniform);
        NeighborQuery q = query(1.5f, 0, uniform);
        NeighborList g = grid(c, q);
        require_same(g, brute(c, q));
        REQUIRE(total_pairs(g) > 0);
      }
    }
  }
}

TEST_CASE("uniform path stays exact when radii are not actually uniform", "[neighbors]") {
  Cloud c = mixed_cloud(1500, 1.0f, 0.005f, 0.05f, 21);
  for (int cap : {0, 8}) {
    NeighborQuery q = query(1.5f, cap, true);
    require_same(grid(c, q), brute(c, q));
  }
}

TEST_CASE("a far outlier makes the box huge but the result exact", "[neighbors]") {
  for (bool uniform : {true, false}) {
    Cloud c = uniform ? uniform_cloud(2000, 1.0f, 0.04f, 31) : mixed_cloud(2000, 1.0f, 0.005f, 0.05f, 31);
    const float rr = uniform ? 0.04f : 0.02f;
    c.add(1.0e6f, -3.0e5f, 2.0e6f, rr);
    c.add(1.0e6f + rr, -3.0e5f, 2.0e6f, rr);  // a second one touching the first, far away
    c.add(-5.0e5f, 0.5f, 0.5f, rr);
    for (int cap : {0, 12}) {
      INFO("uniform " << uniform << " cap " << cap);
      NeighborQuery q = query(1.5f, cap, uniform);
      NeighborList g = grid(c, q), b = brute(c, q);
      require_same(g, b);
      REQUIRE(g.count(2000) == 1);
      REQUIRE(g.indices[g.offsets[2000]] == 2001);
      REQUIRE(g.count(2002) == 0);
    }
  }
}

TEST_CASE("flat layers, lattices with distance ties and coincident points", "[neighbors]") {
  SECTION("a flat layer (zero extent in z)") {
    std::mt19937 rng(41);
    Cloud c;
    for (int i = 0; i < 2000; ++i) c.add(unit(rng), unit(rng), 0.25f, 0.01f);
    for (int cap : {0, 5}) {
      NeighborQuery q = query(1.5f, cap, true);
      require_same(grid(c, q), brute(c, q));
    }
  }
  SECTION("a long thin strip: the wrapped grid folds the thin axis") {
    std::mt19937 rng(43);
    Cloud c;
    for (int i = 0; i < 4000; ++i) c.add(1000.0f * unit(rng), 0.0f, 0.35f * unit(rng), 0.04f);
    for (int cap : {0, 3}) {
      NeighborQuery q = query(1.5f, cap, true);
      NeighborList g = grid(c, q);
      require_same(g, brute(c, q));
      REQUIRE(total_pairs(g) > 500);
    }
  }
  SECTION("a cubic lattice: equal distances are ordered by index") {
    Cloud c;
    for (int z = 0; z < 12; ++z)
      for (int y = 0; y < 12; ++y)
        for (int x = 0; x < 12; ++x) c.add(2.0f * x, 2.0f * y, 2.0f * z, 1.0f);
    for (int cap : {0, 4, 8, 32}) {
      NeighborQuery q = query(1.5f, cap, true);
      NeighborList g = grid(c, q);
      require_same(g, brute(c, q));
      require_same(g, by_definition(c, q));
      // an interior site: 6 face neighbours at distance 2 first, in index order
      const size_t i = (5 * 12 + 5) * 12 + 5;
      REQUIRE(g.count(i) == (cap > 0 ? std::min<size_t>(cap, 18) : 18));
      for (size_t e = 1; e < std::min<size_t>(g.count(i), 6); ++e)
        REQUIRE(g.indices[g.offsets[i] + e - 1] < g.indices[g.offsets[i] + e]);
    }
  }
  SECTION("all points at one spot") {
    Cloud c;
    for (int i = 0; i < 300; ++i) c.add(0.5f, 0.5f, 0.5f, 0.1f);
    for (bool uniform : {true, false})
      for (int cap : {0, 16}) {
        NeighborQuery q = query(1.0f, cap, uniform);
        NeighborList g = grid(c, q);
        require_same(g, brute(c, q));
        REQUIRE(g.count(7) == (cap > 0 ? 16u : 299u));
        REQUIRE(g.indices[g.offsets[7]] == 0);
        REQUIRE(g.indices[g.offsets[7] + 7] == 8);
      }
  }
}

TEST_CASE("degenerate inputs", "[neighbors]") {
  NeighborSearch s;
  NeighborList out;
  NeighborQuery q = query(1.5f, 32, true);
  SECTION("empty") {
    s.find(nullptr, nullptr, 0, q, out);
    REQUIRE(out.offsets == std::vector<uint32_t>{0});
    REQUIRE(out.indices.empty());
    find_neighbors_brute(nullptr, nullptr, 0, q, out);
    REQUIRE(out.offsets == std::vector<uint32_t>{0});
    REQUIRE(cell_sort_order(nullptr, 0, 1.0f).empty());
  }
  SECTION("one point") {
    const float P[3] = {1, 2, 3}, r[1] = {0.5f};
    for (bool uniform : {true, false}) {
      q.uniform_radius = uniform;
      s.find(P, r, 1, q, out);
      REQUIRE(out.offsets == std::vector<uint32_t>{0, 0});
      REQUIRE(out.indices.empty());
    }
    REQUIRE(cell_sort_order(P, 1, 1.0f) == std::vector<uint32_t>{0});
  }
  SECTION("zero scale or zero radii: no pairs") {
    Cloud c = uniform_cloud(200, 1.0f, 0.05f, 3);
    s.find(c.P.data(), c.r.data(), c.size(), query(0.0f, 8, true), out);
    REQUIRE(out.offsets == std::vector<uint32_t>(201, 0));
    std::vector<float> zero(200, 0.0f);
    s.find(c.P.data(), zero.data(), c.size(), query(1.5f, 8, false), out);
    REQUIRE(out.indices.empty());
  }
  SECTION("NaN positions and radii take part in no pair") {
    Cloud c = uniform_cloud(500, 1.0f, 0.06f, 8);
    c.P[3 * 10] = std::nanf("");
    c.r[20] = std::nanf("");
    for (bool uniform : {true, false}) {
      NeighborQuery qq = query(1.5f, 0, uniform);
      NeighborList g = grid(c, qq);
      require_same(g, brute(c, qq));
      REQUIRE(g.count(10) == 0);
      REQUIRE(g.count(20) == 0);
    }
  }
}

TEST_CASE("one search object reused across sizes gives fresh, exact results", "[neighbors]") {
  NeighborSearch s;
  NeighborList out;
  int round = 0;
  for (size_t n : {3000u, 500u, 2500u, 0u, 1200u}) {
    for (bool uniform : {true, false}) {
      Cloud c = uniform ? uniform_cloud(n, 1.0f, 0.04f, uint32_t(n)) : mixed_cloud(n, 1.0f, 0.005f, 0.05f, uint32_t(n));
      NeighborQuery q = query(1.5f, ++round % 3 ? 24 : 0, uniform);
      s.find(c.P.data(), c.r.data(), c.size(), q, out);
      require_same(out, brute(c, q));
    }
  }
}

TEST_CASE("results do not depend on the thread count", "[neighbors]") {
  SECTION("30000 points, uniform and mixed radii") {
    for (bool uniform : {true, false}) {
      Cloud c = uniform ? uniform_cloud(30000, 1.0f, 0.015f, 51) : mixed_cloud(30000, 1.0f, 0.003f, 0.03f, 51);
      for (int cap : {0, 10}) {
        INFO("uniform " << uniform << " cap " << cap);
        NeighborList one = grid(c, query(1.5f, cap, uniform, 1));
        NeighborList two = grid(c, query(1.5f, cap, uniform, 2));
        NeighborList three = grid(c, query(1.5f, cap, uniform, 3));
        NeighborList dflt = grid(c, query(1.5f, cap, uniform, 0));
        require_same(one, two);
        require_same(one, three);
        require_same(one, dflt);
        REQUIRE(total_pairs(one) > c.size());
      }
    }
  }
  SECTION("and equal brute force on a clustered 2-thread run") {
    Cloud c = mixed_cloud(2000, 0.3f, 0.002f, 0.02f, 52);
    NeighborQuery q = query(1.5f, 0, false, 2);
    require_same(grid(c, q), brute(c, q));
  }
}

TEST_CASE("cell sort order is a spatially coherent permutation", "[neighbors]") {
  Cloud c = uniform_cloud(5000, 1.0f, 0.01f, 61);
  std::vector<uint32_t> order = cell_sort_order(c.P.data(), c.size(), 0.05f);
  REQUIRE(order.size() == c.size());
  std::vector<char> seen(c.size(), 0);
  for (uint32_t i : order) {
    REQUIRE(i < c.size());
    REQUIRE(!seen[i]);
    seen[i] = 1;
  }
  double sorted = 0, random = 0;
  for (size_t k = 1; k < c.size(); ++k) {
    sorted += dist(c, order[k - 1], order[k]);
    random += dist(c, k - 1, k);
  }
  sorted /= double(c.size() - 1);
  random /= double(c.size() - 1);
  INFO("mean step sorted " << sorted << " random " << random);
  REQUIRE(sorted < 0.2 * random);
  // deterministic, and points in one cell keep index order
  REQUIRE(cell_sort_order(c.P.data(), c.size(), 0.05f) == order);
  Cloud same;
  for (int i = 0; i < 10; ++i) same.add(0.1f, 0.1f, 0.1f, 1.0f);
  same.add(0.0f, 0.0f, 0.0f, 1.0f);
  std::vector<uint32_t> o2 = cell_sort_order(same.P.data(), same.size(), 0.05f);
  REQUIRE(o2 == std::vector<uint32_t>{10, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9});
  // a far outlier does not break it
  c.add(1.0e7f, 1.0e7f, 1.0e7f, 0.01f);
  std::vector<uint32_t> o3 = cell_sort_order(c.P.data(), c.size(), 0.05f);
  REQUIRE(o3.size() == c.size());
  REQUIRE(o3.back() == c.size() - 1);
}
