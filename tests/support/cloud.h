// A cloud of spheres for the neighbour search's tests (tests/engine/test_neighbors.cpp, the
// OpenCL rows' tests/nodes/grains/test_opencl_neighbours.cpp): positions (n x 3, m) and radii.
#pragma once
#include <cstdint>
#include <random>
#include <vector>

namespace grains::test {

// Uniform float in [0, 1) from the raw generator output (no std distribution: same on every
// standard library).
inline float unit(std::mt19937& rng) { return float(rng() >> 8) * (1.0f / 16777216.0f); }

struct Cloud {
  std::vector<float> P, r;
  size_t size() const { return r.size(); }
  void add(float x, float y, float z, float radius) {
    P.insert(P.end(), {x, y, z});
    r.push_back(radius);
  }
};

}  // namespace grains::test
