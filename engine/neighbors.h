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

// Rows: the neighbours of i are indices[begin[i] .. end[i]), nearest first (ties broken by
// lower index). Neighbour lists are symmetric unless max_neighbors truncates. Rows lie in
// `indices` in no particular order and may leave gaps (the grid search keeps each list where its
// query wrote it instead of copying it into index order), so indices.size() is the storage, at
// least the sum of the row lengths; the rows' contents and order depend only on the input.
struct NeighborList {
  std::vector<uint32_t> begin;    // (n)
  std::vector<uint32_t> end;      // (n)
  std::vector<uint32_t> indices;  // the rows' storage
  // every grain once, in the order its row lies in storage (roughly): a loop over the rows in
  // this order reads the storage front to back
  std::vector<uint32_t> order;  // (n)
  size_t size() const { return begin.size(); }
  size_t count(size_t i) const { return end[i] - begin[i]; }
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
  void find(const float* P, const float* radius, size_t n, const NeighborQuery& q,
            NeighborList& out);

 private:
  struct Level;
  std::vector<uint32_t> keys_, order_, cell_start_;
  std::vector<float> scratch_;
};

// Brute force, O(n^2): the reference the grid paths are tested against.
void find_neighbors_brute(const float* P, const float* radius, size_t n, const NeighborQuery& q,
                          NeighborList& out);

// A permutation that orders points by grid cell (cell size `cell`, row-major over the bounding
// box: x fastest, then y, then z, the neighbour grid's key order), so that neighbouring grains lie
// close in memory. order[k] = the old index of new slot k.
std::vector<uint32_t> cell_sort_order(const float* P, size_t n, float cell);

}  // namespace grains
