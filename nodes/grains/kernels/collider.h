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
 * Friction: the slip relative to the collider's own motion, dx = (p_i - P_i) - v_c dt, joins
 * the grain's other contacts in gr_friction_pass (iterate.h), bounded by the penetration the
 * plane removed in the substep times friction_with_colliders x the `friction` attribute. */
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

/* One Jacobi iteration's collider corrections of grain i (friction is gr_friction_pass's).
 * Adds to *sum, returns how many planes produced a correction; overlap[k] receives the
 * penetration seen in the k-th plane of i's row (0: none). */
GR_INLINE int gr_gather_collider(const gr_grains* g, const gr_params* prm,
                                 const GR_GLOBAL float* p, int i,
                                 float* overlap, gr_float3* sum) {
  int count = 0;
  (void)prm;
  int k;
  gr_uint e;
  gr_float3 pi = gr_load3(p, i);
  for (k = 0; k < GR_MAX_PLANES; ++k) overlap[k] = 0.0f;
  for (e = g->plane_offsets[i], k = 0; e < g->plane_offsets[i + 1]; ++e, ++k) {
    float d = gr_plane_penetration(g, i, e, pi);
    if (!(d > 0.0f)) continue;
    overlap[k] = d;
    *sum = gr_madd(*sum, gr_plane_normal(g, e), d);
    ++count;
  }
  return count;
}

/* Grain i's collider planes into *f (gr_slip_sums): the slip relative to the collider's own
 * motion, dx = (p_i - P_i) - v_c dt, for each plane that pushed it out during the substep
 * (normal[k] > 0, k = the plane's place in i's row: the penetration it removed, summed over the
 * iterations); the collider takes no share. w[k] receives each plane's weighted bound, for
 * impact data. */
GR_INLINE void gr_gather_collider_slip(const gr_grains* g, const gr_params* prm,
                                       const GR_GLOBAL float* p, const GR_GLOBAL float* normal,
                                       int i, gr_slip_sums* f, float* w) {
  int k;
  gr_uint e;
  const gr_float3 di = gr_sub(gr_load3(p, i), gr_load3(g->P, i));
  const float mu = prm->friction_with_colliders * gr_attr(g->friction, i);
  for (k = 0; k < GR_MAX_PLANES; ++k) w[k] = 0.0f;
  for (e = g->plane_offsets[i], k = 0; e < g->plane_offsets[i + 1]; ++e, ++k) {
    if (!(normal[k] > 0.0f)) continue;
    gr_float3 n = gr_plane_normal(g, e);
    gr_float3 vc = gr_make3(g->plane[9 * e + 6], g->plane[9 * e + 7], g->plane[9 * e + 8]);
    gr_float3 dx = gr_madd(di, vc, -prm->dt);
    if (g->plane_slip) dx = gr_add(dx, gr_load3(g->plane_slip, (int)e));
    gr_float3 s = gr_madd(dx, n, -gr_dot(dx, n));
    float sl = gr_length(s);
    if (!(sl > 0.0f)) continue;
    gr_add_slip(f, s, sl, 1.0f, mu, normal[k]);
    w[k] = sl * mu * normal[k];
  }
}

#endif /* GRAINS_KERNELS_COLLIDER_H */
