// The Jacobi path's contact history on the host, grain by grain
// (kernels/history.h), made as a device makes it, bit for bit: this file's source is compiled
// without a multiply and an add fused (CMakeLists.txt), as the device runs the shared functions.
// GrainsSolver::save_history and load_history make it on the device where the rows are there.
#pragma once
#include <cstddef>
#include <cstdint>

#include "nodes/grains/kernels/history.h"

namespace grains {

// grain i's slips saved at the end of the substep into out (gr_save_pair_slips)
void save_pair_slips(const gr_grains& g, const gr_params& prm, const float* p,
                     const uint32_t* pair_normal, size_t i, float* out);

// grain i's collider-plane slips saved at the end of the substep into out (gr_save_plane_slips)
void save_plane_slips(const gr_grains& g, const gr_params& prm, const float* p,
                      const float* collider_normal, size_t i, float* out);

}  // namespace grains
