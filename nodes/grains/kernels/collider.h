/* Grain-collider contact and friction (Macklin et al. 2014 §6.1 eqs. 22-25 with an immovable
 * second body; help page "Friction: With Colliders", "Update Collisions During Iterations").
 *
 * Each grain has at most one collider contact plane per substep (or per iteration when asked):
 * surface point x_s, outward unit normal n and the collider's surface velocity v_c there.
 * Contact: penetration d = r_i - (p_i - x_s) . n > 0 pushes the grain out by d n in full (the
 * collider has infinite mass: share 1). Colliders must always hold, so the contact is not scaled
 * by the repulsion weight or stiffness.
 * Friction: the slip relative to the collider's own motion, dx = (p_i - P_i) - v_c dt, is
 * treated as eqs. 23-25 with bound d' = friction_with_colliders * friction_i * d: removed in
 * full when |dx_t| < static_threshold * d', else by min(1, scale_kinetic * d' / |dx_t|). */
#ifndef GRAINS_KERNELS_COLLIDER_H
#define GRAINS_KERNELS_COLLIDER_H
#include "contact.h"

GR_INLINE gr_float3 gr_plane_normal(const gr_grains* g, int i) {
  return gr_make3(g->plane[9 * i + 3], g->plane[9 * i + 4], g->plane[9 * i + 5]);
}

/* penetration of a grain centred at x into i's plane (negative: apart) */
GR_INLINE float gr_plane_penetration(const gr_grains* g, int i, gr_float3 x) {
  gr_float3 xs = gr_make3(g->plane[9 * i], g->plane[9 * i + 1], g->plane[9 * i + 2]);
  return g->radius[i] - gr_dot(gr_sub(x, xs), gr_plane_normal(g, i));
}

GR_INLINE gr_float3 gr_collider_friction(const gr_grains* g, const gr_params* prm,
                                         const GR_GLOBAL float* p, int i, float d) {
  gr_float3 n = gr_plane_normal(g, i);
  gr_float3 vc = gr_make3(g->plane[9 * i + 6], g->plane[9 * i + 7], g->plane[9 * i + 8]);
  gr_float3 dx = gr_madd(gr_sub(gr_load3(p, i), gr_load3(g->P, i)), vc, -prm->dt);
  float bound = prm->friction_with_colliders * gr_attr(g->friction, i) * d;
  return gr_friction(dx, n, bound, prm->static_threshold, prm->scale_kinetic);
}

/* One Jacobi iteration's collider correction of grain i (with friction when `with_friction`).
 * Adds to *sum, returns 1 when it produced a correction; *overlap receives the penetration seen
 * (0: none). */
GR_INLINE int gr_gather_collider(const gr_grains* g, const gr_params* prm,
                                 const GR_GLOBAL float* p, int i, int with_friction,
                                 float* overlap, gr_float3* sum) {
  *overlap = 0.0f;
  gr_float3 n = gr_plane_normal(g, i);
  if (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f) return 0;
  float d = gr_plane_penetration(g, i, gr_load3(p, i));
  if (!(d > 0.0f)) return 0;
  *overlap = d;
  gr_float3 corr = gr_scale(n, d);
  if (with_friction && prm->friction_with_colliders > 0.0f)
    corr = gr_add(corr, gr_collider_friction(g, prm, p, i, d));
  *sum = gr_add(*sum, corr);
  return 1;
}

/* The friction pass after the loop (accurate_friction off), bounded by the accumulated
 * penetration `normal` (see gr_gather_pair_friction). */
GR_INLINE int gr_gather_collider_friction(const gr_grains* g, const gr_params* prm,
                                          const GR_GLOBAL float* p, float normal, int i,
                                          gr_float3* sum) {
  gr_float3 n = gr_plane_normal(g, i);
  if (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f) return 0;
  if (!(normal > 0.0f)) return 0;
  gr_float3 corr = gr_collider_friction(g, prm, p, i, normal);
  if (corr.x == 0.0f && corr.y == 0.0f && corr.z == 0.0f) return 0;
  *sum = gr_add(*sum, corr);
  return 1;
}

#endif /* GRAINS_KERNELS_COLLIDER_H */
