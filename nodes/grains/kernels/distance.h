/* Explicit distance constraints (help page "Explicit Constraints"; Müller et al. 2007, "Position
 * Based Dynamics", §3.3; Macklin et al. 2014 eq. 12 for the Jacobi gather).
 *
 * A constraint is a 2-point polyline primitive (i, j) with rest length L:
 *   C = |x_ij| - L,  n = x_ij / |x_ij|  (from j to i),
 *   dp_i = -w_i / (w_i + w_j) * C * n
 *          * explicit_constraints_weight * constraintweight_i
 *          * min(1, explicit_constraints_stiffness * constraintstiffness_i / (substeps * iterations)).
 * The weight and stiffness attributes are read per particle, not per constraint (help page): a
 * grain with constraintweight 0 ignores its constraints while its partners still pull on it.
 * Strain (the `strain` primitive attribute, DESIGN §4): e = (|x_ij| - L) / L (0 when L = 0). */
#ifndef GRAINS_KERNELS_DISTANCE_H
#define GRAINS_KERNELS_DISTANCE_H
#include "mass_shock.h"

/* i's constraint scale: weight x stiffness fraction, both with their point attributes */
GR_INLINE float gr_constraint_scale(const gr_grains* g, const gr_params* prm, int i) {
  float k = prm->explicit_constraints_stiffness * gr_attr(g->constraintstiffness, i);
  float fraction = gr_max(0.0f, gr_min(1.0f, k / prm->stiffness_denominator));
  return prm->explicit_constraints_weight * gr_attr(g->constraintweight, i) * fraction;
}

/* the strain of a constraint between points a and b with rest length L */
GR_INLINE float gr_strain(gr_float3 a, gr_float3 b, float L) {
  /* at most the largest float: a rest length of a few subnormal units made it infinite */
  return L > 0.0f ? gr_min((gr_length(gr_sub(a, b)) - L) / L, 3.4028234663852886e38f) : 0.0f;
}

/* whether i and j share an explicit constraint (for skipping their contact) */
GR_INLINE int gr_constrained(const gr_grains* g, int i, int j) {
  gr_uint k;
  for (k = g->con_offsets[i]; k < g->con_offsets[i + 1]; ++k)
    if ((int)g->con_other[k] == j) return 1;
  return 0;
}

/* One Jacobi iteration's constraint corrections of grain i, read from the iterate p. Adds to
 * *sum, returns how many constraints produced a nonzero correction. Coincident endpoints have
 * no direction and are skipped (the contact or other constraints separate them first). */
GR_INLINE int gr_gather_constraints(const gr_grains* g, const gr_params* prm,
                                    const GR_GLOBAL float* p, int i, gr_float3* sum) {
  float scale = gr_constraint_scale(g, prm, i);
  if (!(scale > 0.0f)) return 0;
  int count = 0;
  gr_float3 pi = gr_load3(p, i);
  gr_uint k;
  for (k = g->con_offsets[i]; k < g->con_offsets[i + 1]; ++k) {
    int j = (int)g->con_other[k];
    gr_float3 xij = gr_sub(pi, gr_load3(p, j));
    float dist = gr_length(xij);
    if (!(dist > 0.0f)) continue;
    float c = dist - g->restlength[g->con_prim[k]];
    float s = gr_pair_share(g, prm, i, j) * c * scale;
    if (s == 0.0f) continue;
    *sum = gr_madd(*sum, xij, -s / dist);
    ++count;
  }
  return count;
}

#endif /* GRAINS_KERNELS_DISTANCE_H */
