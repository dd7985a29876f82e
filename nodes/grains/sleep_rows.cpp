#include "nodes/grains/sleep_rows.h"

#include "nodes/grains/kernels/row_stats.h"

namespace grains {

uint32_t sleep_row_near(const NeighborList& rows, const float* P, const float* radius, size_t k,
                        float reach) {
  return gr_row_near(P, radius, rows.offsets.data(), rows.indices.data(), static_cast<int>(k),
                     reach);
}

bool sleep_row_fast_near(const NeighborList& rows, const float* P, const float* radius,
                         const uint8_t* fast, size_t k, float reach) {
  return gr_row_fast_near(P, radius, rows.offsets.data(), rows.indices.data(), fast,
                          static_cast<int>(k), reach) != 0;
}

float rows_moved2(const float* p, const float* b, size_t n, int threads) {
  float moved2 = 0.0f;
  const long ln = static_cast<long>(n);
#pragma omp parallel for schedule(static) num_threads(threads) reduction(max : moved2)
  for (long i = 0; i < ln; ++i)
    gr_rows_moved(p, b, static_cast<int>(i), static_cast<int>(i) + 1, &moved2);
  return moved2;
}

}  // namespace grains
