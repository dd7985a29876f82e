/* One Jacobi iteration of grain i (DESIGN §4 step 3; Macklin et al. 2014 §4.2 eq. 12):
 *   p_i' = p_i + over_relaxation / n_i * sum_c dp_i,c,
 * n_i = the number of constraints that produced a nonzero correction (1 when
 * disable_constraint_averaging). Each grain reads the previous iterate of its neighbours and
 * writes only its own next iterate (and its own rows of the overlap accumulators): gather, no
 * atomics, the same for any thread count. */
#ifndef GRAINS_KERNELS_ITERATE_H
#define GRAINS_KERNELS_ITERATE_H
#include "collider.h"

/* Accumulated contact overlaps for the friction pass after the loop (accurate_friction off);
 * all null when not needed. */
typedef struct {
  GR_GLOBAL float* pair_iteration; /* (neighbour entries) overlap this iteration, scratch */
  GR_GLOBAL float* pair;           /* (neighbour entries) sum over iterations of overlap / n_i */
  GR_GLOBAL float* collider;       /* (n x GR_MAX_PLANES) the same for the collider planes */
} gr_normal_sums;

GR_INLINE gr_float3 gr_average(gr_float3 p, gr_float3 sum, int count, float omega,
                               int disable_averaging) {
  if (count == 0) return p;
  return gr_madd(p, sum, disable_averaging ? omega : omega / (float)count);
}

/* constraint loop: contacts (+ friction when with_friction), clumping, collider plane, explicit
 * constraints */
GR_INLINE gr_float3 gr_iterate(const gr_grains* g, const gr_params* prm, const GR_GLOBAL float* p,
                               int i, int with_friction, const gr_normal_sums* acc) {
  gr_float3 sum = gr_make3(0.0f, 0.0f, 0.0f);
  int count = 0;
  float pen[GR_MAX_PLANES];
  if (g->nbr_offsets) count += gr_gather_pairs(g, prm, p, i, with_friction, acc->pair_iteration, &sum);
  if (g->plane) count += gr_gather_collider(g, prm, p, i, with_friction, pen, &sum);
  if (g->con_offsets) count += gr_gather_constraints(g, prm, p, i, &sum);
  if (acc->pair || acc->collider) {
    float share = (prm->disable_averaging || count == 0) ? 1.0f : 1.0f / (float)count;
    if (acc->pair && g->nbr_offsets) {
      gr_uint k;
      for (k = g->nbr_offsets[i]; k < g->nbr_offsets[i + 1]; ++k)
        acc->pair[k] += acc->pair_iteration[k] * share;
    }
    if (acc->collider && g->plane) {
      int k;
      for (k = 0; k < GR_MAX_PLANES; ++k) acc->collider[GR_MAX_PLANES * i + k] += pen[k] * share;
    }
  }
  return gr_average(gr_load3(p, i), sum, count, prm->over_relaxation, prm->disable_averaging);
}

/* the friction pass after the loop (accurate_friction off): averaged, not over-relaxed */
GR_INLINE gr_float3 gr_friction_pass(const gr_grains* g, const gr_params* prm,
                                     const GR_GLOBAL float* p, const gr_normal_sums* acc, int i) {
  gr_float3 sum = gr_make3(0.0f, 0.0f, 0.0f);
  int count = 0;
  if (acc->pair && g->nbr_offsets) count += gr_gather_pair_friction(g, prm, p, acc->pair, i, &sum);
  if (acc->collider && g->plane)
    count += gr_gather_collider_friction(g, prm, p, acc->collider + GR_MAX_PLANES * i, i, &sum);
  return gr_average(gr_load3(p, i), sum, count, 1.0f, prm->disable_averaging);
}

#endif /* GRAINS_KERNELS_ITERATE_H */
