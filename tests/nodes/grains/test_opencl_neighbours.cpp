// The neighbour rows found on an OpenCL device (opencl::Iterations::find_neighbours,
// kernels/grid.h) against the CPU path's search (engine/neighbors.cpp), on PoCL's CPU device:
// the pair test and a row's order are one definition (engine/pair_test.h), so the rows must be
// the same lists bit for bit, whatever the grid: a dense box, a far outlier that makes the
// device's grid wrap, a flat layer, mixed radii, grains on one spot, positions and radii that
// are not finite, and every max_neighbors cut.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "engine/neighbors.h"
#include "nodes/grains/opencl/iterations.h"
#include "tests/support/cloud.h"
#include "tests/support/support.h"

using namespace grains;
using test::Cloud;
using test::unit;

namespace {

// n grains uniform in a box of sides sx, sy, sz, radii log-uniform in [rmin, rmax]
Cloud cloud(size_t n, float sx, float sy, float sz, float rmin, float rmax, uint32_t seed) {
  std::mt19937 rng(seed);
  Cloud c;
  const float ratio = std::log(rmax / rmin);
  for (size_t i = 0; i < n; ++i) {
    const float x = sx * unit(rng), y = sy * unit(rng), z = sz * unit(rng);
    c.add(x, y, z, rmin * std::exp(ratio * unit(rng)));
  }
  return c;
}

// the rows both ways; fails the test when the device cannot build them
void same_rows(opencl::Iterations& device, const Cloud& c, const NeighborQuery& q) {
  NeighborSearch search;
  NeighborList cpu, gpu;
  search.find(c.P.data(), c.r.data(), c.size(), q, cpu);
  REQUIRE(device.find_neighbours(c.P.data(), c.r.data(), c.size(), q, gpu));
  REQUIRE(gpu.offsets == cpu.offsets);
  REQUIRE(gpu.indices == cpu.indices);
}

}  // namespace

TEST_CASE("use_opencl: the device's neighbour rows are the CPU search's, bit for bit", "[opencl]") {
  static opencl::Iterations device;  // built once for all the sections
  NeighborQuery q;
  q.query_scale = 1.1f;
  q.max_neighbors = 64;
  q.threads = 1;
  // a dense box: about 12 neighbours a grain at r = 0.01 (the rows' lengths are not trivial)
  const Cloud box = cloud(20000, 0.42f, 0.42f, 0.42f, 0.01f, 0.01f, 1);
  {
    NeighborSearch search;
    NeighborList rows;
    search.find(box.P.data(), box.r.data(), box.size(), q, rows);
    INFO("pairs a grain " << double(rows.indices.size()) / double(box.size()));
    REQUIRE(rows.indices.size() > 8 * box.size());
  }
  SECTION("a dense box, uniform radius") {
    same_rows(device, box, q);
  }
  SECTION("cut at max_neighbors 4, and no cut") {
    q.max_neighbors = 4;
    same_rows(device, box, q);
    q.max_neighbors = 0;
    same_rows(device, box, q);
  }
  SECTION("query scales that reach far and not at all") {
    q.query_scale = 2.5f;
    same_rows(device, box, q);
    q.query_scale = 0.0f;
    same_rows(device, box, q);
  }
  SECTION("radii over a factor of 10") {
    same_rows(device, cloud(8000, 0.6f, 0.6f, 0.6f, 0.004f, 0.04f, 2), q);
  }
  SECTION("a far outlier: the grid wraps") {
    Cloud c = box;
    c.add(1.0e6f, -3.0e5f, 2.0e4f, 0.01f);
    c.add(1.0e6f + 0.015f, -3.0e5f, 2.0e4f, 0.01f);  // and a neighbour of it there
    same_rows(device, c, q);
  }
  SECTION("a flat layer, wide in x and z") {
    same_rows(device, cloud(20000, 20.0f, 0.05f, 20.0f, 0.05f, 0.05f, 3), q);
  }
  SECTION("grains on one spot, and positions and radii that are not finite") {
    Cloud c = cloud(2000, 0.3f, 0.3f, 0.3f, 0.01f, 0.01f, 4);
    for (int k = 0; k < 100; ++k) c.add(0.1f, 0.1f, 0.1f, 0.01f);  // 100 coincident grains
    const float nan = std::numeric_limits<float>::quiet_NaN(),
                inf = std::numeric_limits<float>::infinity();
    c.add(nan, 0.1f, 0.1f, 0.01f);
    c.add(0.1f, inf, 0.1f, 0.01f);
    c.add(-inf, 0.1f, 0.1f, 0.01f);
    c.add(0.2f, 0.2f, 0.2f, nan);
    c.add(0.2f, 0.2f, 0.21f, 0.0f);
    c.add(0.2f, 0.2f, 0.22f, -0.01f);
    q.max_neighbors = 0;
    same_rows(device, c, q);
    q.max_neighbors = 16;
    same_rows(device, c, q);
  }
  SECTION("no grains, one grain, no radius") {
    same_rows(device, Cloud{}, q);
    Cloud one;
    one.add(1, 2, 3, 0.1f);
    same_rows(device, one, q);
    Cloud zero = box;
    for (float& r : zero.r) r = 0.0f;
    same_rows(device, zero, q);
  }
}

TEST_CASE("use_opencl: rows whose buffers exceed the device's largest are left to the host",
          "[opencl]") {
  // 20,000 grains of about 12 neighbours: their rows' sort keys (8 bytes an entry) take 1.8 MiB,
  // over a cap of 1 MiB; the grains themselves (16 bytes each) fit. find_neighbours says it
  // cannot and the substep searches on the host, which finds the same rows
  // ("use_opencl: gauss_seidel's contacts split over device buffers give the same bits").
  test::ScopedEnv cap("GRAINS_OPENCL_MAX_BUFFER_MIB", "1");
  opencl::Iterations device;
  const Cloud box = cloud(20000, 0.42f, 0.42f, 0.42f, 0.01f, 0.01f, 1);
  NeighborQuery q;
  q.query_scale = 1.1f;
  NeighborList rows;
  CHECK_FALSE(device.find_neighbours(box.P.data(), box.r.data(), box.size(), q, rows));
  const Cloud few = cloud(2000, 0.2f, 0.2f, 0.2f, 0.01f, 0.01f, 2);  // under the cap: found
  same_rows(device, few, q);
}
