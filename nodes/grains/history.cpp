#include "nodes/grains/history.h"

namespace grains {

void save_pair_slips(const gr_grains& g, const gr_params& prm, const float* p,
                     const uint32_t* pair_normal, size_t i, float* out) {
  gr_save_pair_slips(&g, &prm, p, pair_normal, static_cast<int>(i), out);
}

void save_plane_slips(const gr_grains& g, const gr_params& prm, const float* p,
                      const float* collider_normal, size_t i, float* out) {
  gr_save_plane_slips(&g, &prm, p, collider_normal, static_cast<int>(i), out);
}

}  // namespace grains
