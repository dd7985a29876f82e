/* Grain-collider contact and friction (Macklin et al. 2014 §6.1 eqs. 22-25 with an immovable
 * second body; help page "Friction: With Colliders", "Update Collisions During Iterations").
 *
 * Each grain has up to GR_MAX_PLANES collider contact planes per substep (or per iteration when
 * asked), the nearest first (a compact row per grain, gr_grains::plane_offsets), so a grain in a corner or an edge between walls and ground feels
 * every surface it touches (FleX keeps six): surface point x_s, outward unit normal n and the
 * collider's surface velocity v_c there. Each plane is one constraint in the average.
 * Contact: penetration d = r_i - (p_i - x_s) . n > 0 pushes the grain out by d n in full (the
 * collider has infinite mass: share 1). Colliders must always hold, so the contact is not scaled
 * by the repulsion weight or stiffness.
 * Friction: the slip relative to the collider's own motion, dx = (p_i - P_i) - v_c dt, is
 * treated as eqs. 23-25 with bound d' = friction_with_colliders * friction_i * d: removed in
 * full when |dx_t| < static_threshold * d', else by min(1, scale_kinetic * d' / |dx_t|). */
#ifndef GRAINS_KERNELS_COLLIDER_H
#define GRAINS_KERNELS_COLLIDER_H
#include "contact.h"

/* plane entry e: 9 floats (surface point, normal, surface velocity) */
GR_INLINE gr_float3 gr_plane_normal(const gr_grains* g, gr_uint e) {
  return gr_make3(g->plane[9 * e + 3], g->plane[9 * e + 4], g->plane[9 * e + 5]);
}

/* penetration of grain i centred at x into plane entry e (negative: apart) */
GR_INLINE float gr_plane_penetration(const gr_grains* g, int i, gr_uint e, gr_float3 x) {
  gr_float3 xs = gr_make3(g->plane[9 * e], g->plane[9 * e + 1], g->plane[9 * e + 2]);
  return g->radius[i] - gr_dot(gr_sub(x, xs), gr_plane_normal(g, e));
}

GR_INLINE gr_float3 gr_collider_friction(const gr_grains* g, const gr_params* prm,
                                         const GR_GLOBAL float* p, int i, gr_uint e, float d) {
  gr_float3 n = gr_plane_normal(g, e);
  gr_float3 vc = gr_make3(g->plane[9 * e + 6], g->plane[9 * e + 7], g->plane[9 * e + 8]);
  gr_float3 dx = gr_madd(gr_sub(gr_load3(p, i), gr_load3(g->P, i)), vc, -prm->dt);
  float bound = prm->friction_with_colliders * gr_attr(g->friction, i) * d;
  return gr_friction(dx, n, bound, prm->static_threshold, prm->scale_kinetic);
}

/* One Jacobi iteration's collider corrections of grain i (with friction when `with_friction`).
 * Adds to *sum, returns how many planes produced a correction; overlap[k] receives the
 * penetration seen in the k-th plane of i's row (0: none). */
GR_INLINE int gr_gather_collider(const gr_grains* g, const gr_params* prm,
                                 const GR_GLOBAL float* p, int i, int with_friction,
                                 float* overlap, gr_float3* sum) {
  int count = 0;
  int k;
  gr_uint e;
  gr_float3 pi = gr_load3(p, i);
  for (k = 0; k < GR_MAX_PLANES; ++k) overlap[k] = 0.0f;
  for (e = g->plane_offsets[i], k = 0; e < g->plane_offsets[i + 1]; ++e, ++k) {
    float d = gr_plane_penetration(g, i, e, pi);
    if (!(d > 0.0f)) continue;
    overlap[k] = d;
    gr_float3 corr = gr_scale(gr_plane_normal(g, e), d);
    if (with_friction && prm->friction_with_colliders > 0.0f)
      corr = gr_add(corr, gr_collider_friction(g, prm, p, i, e, d));
    *sum = gr_add(*sum, corr);
    ++count;
  }
  return count;
}

/* The friction pass after the loop (accurate_friction off), bounded by each plane's accumulated
 * penetration normal[k], k = the plane's place in i's row (see gr_gather_pair_friction). */
GR_INLINE int gr_gather_collider_friction(const gr_grains* g, const gr_params* prm,
                                          const GR_GLOBAL float* p, const GR_GLOBAL float* normal,
                                          int i, gr_float3* sum) {
  int count = 0;
  int k;
  gr_uint e;
  for (e = g->plane_offsets[i], k = 0; e < g->plane_offsets[i + 1]; ++e, ++k) {
    if (!(normal[k] > 0.0f)) continue;
    gr_float3 corr = gr_collider_friction(g, prm, p, i, e, normal[k]);
    if (corr.x == 0.0f && corr.y == 0.0f && corr.z == 0.0f) continue;
    *sum = gr_add(*sum, corr);
    ++count;
  }
  return count;
}

#endif /* GRAINS_KERNELS_COLLIDER_H */
