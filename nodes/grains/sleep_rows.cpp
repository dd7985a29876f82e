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

}  // namespace grains
