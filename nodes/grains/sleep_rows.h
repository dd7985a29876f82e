// The grains node's sleeping test on the host, grain by grain (kernels/sleep.h), and its reads
// along neighbour rows (kernels/row_stats.h), made as a device makes them, bit for bit: this
// file's source is compiled without a multiply and an add fused (CMakeLists.txt), as the device
// runs the shared functions. GrainsSolver::sleep_rows_on_device makes them on the device while the
// rows are there. The solver's Verlet test (GrainsSolver::keep_rows) is made here alike.
#pragma once
#include <cstddef>
#include <cstdint>

#include "engine/neighbors.h"
#include "nodes/grains/kernels/sleep.h"

namespace grains {

// grain k's neighbours in `rows` within reach x (r_k + r_j) at the world positions P (n x 3)
// with the radii `radius`
uint32_t sleep_row_near(const NeighborList& rows, const float* P, const float* radius, size_t k,
                        float reach);
// whether one of them flagged in `fast` (a byte a grain) lies within reach x (r_k + r_j)
bool sleep_row_fast_near(const NeighborList& rows, const float* P, const float* radius,
                         const uint8_t* fast, size_t k, float reach);

// kernels/sleep.h's stages of grain k (gr_sleep_begin, gr_sleep_settle, gr_sleep_stay), made
// as a device makes them
bool sleep_begin(const gr_sleep_params& sp, const gr_sleep& s, size_t k, const float* P);
bool sleep_settle(const gr_sleep_params& sp, const gr_sleep& s, size_t k, float* P, float* v);
bool sleep_stay(const gr_sleep_params& sp, const gr_sleep& s, size_t k, const float* P, float* v);
// whether collider c (which moved this substep; `mesh` its mesh, or null) reaches grain k at
// its end P (gr_sleep_collider_near), made as a device makes it
bool sleep_collider_near(const gr_sleep_params& sp, const gr_sleep& s, size_t k,
                         const gr_collider& c, const void* mesh, const float* P);

// the largest squared distance between the positions p and b (n x 3 each) of one grain
// (gr_rows_moved), over `threads` threads: the same float whatever their number
float rows_moved2(const float* p, const float* b, size_t n, int threads);

}  // namespace grains
