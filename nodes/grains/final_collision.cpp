// The final collision test on the CPU (kernels/final_collision.h), for GrainsSolver::write_back.
// This file, like planes.cpp, is compiled without contraction of multiplies and adds
// (CMakeLists.txt), as an OpenCL device runs the shared functions (GR_SHAPE_EXACT).
#include "nodes/grains/kernels/final_collision.h"

#include "nodes/grains/substep_context.h"

namespace grains {

int32_t final_collision(const gr_collider* colliders, const void* const* meshes, size_t count,
                        const Vec3& a, Vec3& b, Vec3& v, float r, float mu, const gr_params& prm,
                        Vec3* hit_n) {
  const float from[3] = {a.x, a.y, a.z};
  float to[3] = {b.x, b.y, b.z}, vel[3] = {v.x, v.y, v.z}, n[3] = {0.0f, 0.0f, 0.0f};
  const int32_t hit = gr_final_collisions(colliders, static_cast<int>(count), from, to, vel, r, mu,
                                          prm.static_threshold, prm.scale_kinetic, n, meshes);
  if (hit >= 0) *hit_n = {n[0], n[1], n[2]};
  b = {to[0], to[1], to[2]};
  v = {vel[0], vel[1], vel[2]};
  return hit;
}

}  // namespace grains
