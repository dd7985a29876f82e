// Impact data on the CPU (kernels/impact.h), for gauss_seidel and GrainsSolver::write_back. This
// file, like final_collision.cpp, is compiled without contraction of multiplies and adds
// (CMakeLists.txt), as an OpenCL device runs the shared functions (GR_SHAPE_EXACT).
#include "nodes/grains/kernels/impact.h"

#include "nodes/grains/substep_context.h"

namespace grains {

void impact_loads(const gr_grains& g, const gr_seq_contact* seq, size_t count, float* dx) {
  for (size_t k = 0; k < count; ++k) gr_seq_impact_load(&g, &seq[k], dx);
}

void impact_slots(const gr_grains& g, float dt, size_t i, const float* dx,
                  const int32_t* plane_collider, const Vec3& b, const Vec3& v, const Vec3& v_loop,
                  int32_t hit, const Vec3& hit_n, GrainsData& d) {
  const float end[3] = {b.x, b.y, b.z}, vel[3] = {v.x, v.y, v.z},
              before[3] = {v_loop.x, v_loop.y, v_loop.z}, n[3] = {hit_n.x, hit_n.y, hit_n.z};
  gr_impact_slots(&g, dt, static_cast<int>(i), dx, plane_collider, end, vel, before, hit, n,
                  d.impact_collider, d.impact_impulse, d.impact_normal, d.impact_point);
}

}  // namespace grains
