/* Impact data (help page "Add Impact Data"; also collision feedback): each grain has
 * GR_MAX_PLANES slots, one a collider plane of its row. Over the substep a slot gathers what its
 * plane moved the grain (dx, m); at the end it becomes that collider's momentum on the grain: dx
 * / dt x mass, plus, for the collider the final collision test acted on last, the velocity the
 * test changed (v - v_loop) x mass, in that collider's slot or the first free one.
 *
 * The CPU runs these in GrainsSolver::write_back and gauss_seidel (through impact.cpp, compiled
 * without contraction), an OpenCL device in gr_k_impact_loads and gr_k_final_collision: like the
 * final collision test they fuse no multiply and add (GR_SHAPE_EXACT), so both make the same
 * floats from the same inputs. */
#ifndef GRAINS_KERNELS_IMPACT_H
#define GRAINS_KERNELS_IMPACT_H
#include "collider.h"
#include "sequential.h"
#if defined(GR_OPENCL)
#include "collider_shape.h"
#else
#include "engine/collider_shape.h"
#endif

/* gauss_seidel: what collider contact q applied over the substep, its normal load along its
 * plane's normal plus its tangential load, into its slot of dx (3 GR_MAX_PLANES floats a grain,
 * zero where no contact writes; a plane has one contact a grain, so no two write one slot). A
 * pair, or a contact that took back all it pushed, writes nothing. */
GR_INLINE void gr_seq_impact_load(const gr_grains* g, const GR_GLOBAL gr_seq_contact* q,
                                  GR_GLOBAL float* dx) {
  GR_SHAPE_EXACT
  gr_float3 n;
  gr_uint slot;
  if (q->j >= 0) return;
  if (!(q->ln > 0.0f) && q->lt[0] == 0.0f && q->lt[1] == 0.0f && q->lt[2] == 0.0f) return;
  n = gr_plane_normal(g, q->e);
  slot = 3u * (GR_MAX_PLANES * (gr_uint)q->i + (q->e - g->plane_offsets[q->i]));
  dx[slot] = n.x * q->ln + q->lt[0];
  dx[slot + 1] = n.y * q->ln + q->lt[1];
  dx[slot + 2] = n.z * q->ln + q->lt[2];
}

/* Grain i's slots at the substep's end: dx its gathered moves (3 GR_MAX_PLANES floats), which
 * its plane row (g->plane_offsets, g->plane, plane_collider: each entry's collider) names; b
 * its end position (world), v its velocity after the final collision test, v_loop before it;
 * hit the last collider the test acted on (-1: none) along hit_n. Out, a slot each: the
 * collider, the momentum (N s), the plane's normal and the contact point on the collider's
 * surface, b - normal x radius; an empty slot holds -1 and zeros. */
GR_INLINE void gr_impact_slots(const gr_grains* g, float dt, int i, const GR_GLOBAL float* dx,
                               const GR_GLOBAL int* plane_collider, const float* b, const float* v,
                               const float* v_loop, int hit, const float* hit_n,
                               GR_GLOBAL int* collider, GR_GLOBAL float* impulse,
                               GR_GLOBAL float* normal, GR_GLOBAL float* point) {
  GR_SHAPE_EXACT
  const gr_uint row = g->plane_offsets[i];
  const int planes = (int)(g->plane_offsets[i + 1] - row);
  const float m = g->mass[i], r = g->radius[i];
  int q, k, hit_slot = -1;
  for (q = 0; q < GR_MAX_PLANES; ++q) {
    const int slot = GR_MAX_PLANES * i + q;
    const int c = q < planes ? plane_collider[row + (gr_uint)q] : -1;
    float dv[3] = {0.0f, 0.0f, 0.0f}, n[3] = {0.0f, 0.0f, 0.0f};
    int any;
    if (c >= 0) {
      const GR_GLOBAL float* pl = g->plane + 9u * (row + (gr_uint)q);
      for (k = 0; k < 3; ++k) dv[k] = dx[3 * slot + k] / dt, n[k] = pl[3 + k];
    }
    if (hit >= 0 && hit_slot < 0 && (c == hit || c < 0)) {
      hit_slot = q;
      for (k = 0; k < 3; ++k) dv[k] = dv[k] + (v[k] - v_loop[k]);
      if (c < 0)
        for (k = 0; k < 3; ++k) n[k] = hit_n[k];
    }
    any = !(dv[0] == 0.0f && dv[1] == 0.0f && dv[2] == 0.0f);
    collider[slot] = any ? (c >= 0 ? c : hit) : -1;
    for (k = 0; k < 3; ++k) {
      impulse[3 * slot + k] = any ? dv[k] * m : 0.0f;
      normal[3 * slot + k] = any ? n[k] : 0.0f;
      point[3 * slot + k] = any ? b[k] - n[k] * r : 0.0f;
    }
  }
}

#endif /* GRAINS_KERNELS_IMPACT_H */
