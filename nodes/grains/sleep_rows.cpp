#include "nodes/grains/sleep_rows.h"

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

bool sleep_begin(const gr_sleep_params& sp, const gr_sleep& s, size_t k, const float* P) {
  const int i = static_cast<int>(k);
  return gr_sleep_begin(&sp, &s, i, gr_load3(P, i)) != 0;
}

bool sleep_settle(const gr_sleep_params& sp, const gr_sleep& s, size_t k, float* P, float* v) {
  return gr_sleep_settle(&sp, &s, static_cast<int>(k), P, v) != 0;
}

bool sleep_stay(const gr_sleep_params& sp, const gr_sleep& s, size_t k, const float* P, float* v) {
  return gr_sleep_stay(&sp, &s, static_cast<int>(k), P, v) != 0;
}

bool sleep_collider_near(const gr_sleep_params& sp, const gr_sleep& s, size_t k,
                         const gr_collider& c, const void* mesh, const float* P) {
  return gr_sleep_collider_near(&sp, &s, static_cast<int>(k), &c, P, mesh) != 0;
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
