// Neighbour search over a compact set of spheres: pairs closer than
// query_scale * (r_i + r_j), at most max_neighbors nearest per particle.
// Two paths: a uniform grid with cell size = the largest interaction distance when all radii are
// equal (assume_uniform_radius), and a multi-level grid for mixed radii (10x size ratios), where
// each particle is binned in the level matching its radius and queries every level.
// Both return exactly the pairs brute force returns, in a deterministic order.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

namespace grains {

// Compressed rows: neighbours of i are indices[offsets[i] .. offsets[i+1]), nearest first
// (ties broken by lower index). Neighbour lists are symmetric unless max_neighbors truncates.
struct NeighborList {
  std::vector<uint32_t> offsets;  // (n + 1)
  std::vector<uint32_t> indices;  // (total pairs counted from both ends)
  size_t count(size_t i) const { return offsets[i + 1] - offsets[i]; }
};

struct NeighborQuery {
  float query_scale = 1.0f;     // pair distance threshold = query_scale * (r_i + r_j)
  int max_neighbors = 64;       // keep at most this many nearest per particle (<= 0: no cap)
  bool uniform_radius = false;  // true: all radii equal, single-level grid
  int threads = 0;              // 0: OpenMP default
};

// P: (n x 3) positions, radius: (n) radii. Rebuilds its grid on each call; keeps its buffers so
// repeated calls allocate nothing once sizes settle.
class NeighborSearch {
 public:
  // store: a buffer the lists are kept in until they are copied into `out` (nullptr: the
  // search's own); for a caller with a buffer of about 4 bytes per neighbour entry that is idle
  // during the search. Its contents are unspecified afterwards; its capacity is kept.
  void find(const float* P, const float* radius, size_t n, const NeighborQuery& q,
            NeighborList& out, std::vector<uint32_t>* store = nullptr);

 private:
  struct Level;
  std::vector<uint32_t> keys_, order_, cell_start_;
  std::vector<float> scratch_;
};

// Brute force, O(n^2): the reference the grid paths are tested against.
void find_neighbors_brute(const float* P, const float* radius, size_t n, const NeighborQuery& q,
                          NeighborList& out);

// A permutation that orders points by grid cell (cell size `cell`, z-order within the bounding
// box), so that neighbouring grains lie close in memory. order[k] = the old index of new slot k.
std::vector<uint32_t> cell_sort_order(const float* P, size_t n, float cell);

}  // namespace grains
