/* Clumping (help page "Clumping"): grains that are apart but within the neighbour query range,
 * r_i + r_j <= |x_ij| < neighbor_query_scale * (r_i + r_j), are pulled back to contact as by a
 * one-sided distance constraint C = |x_ij| - (r_i + r_j) (Macklin et al. 2014 eq. 22 with the
 * sign reversed):
 *   dp_i = -w_i / (w_i + w_j) * (|x_ij| - (r_i + r_j)) * n_ij
 *          * clumping_weight * attractionweight_i
 *          * min(1, clumping_stiffness * attractionstiffness_i / (substeps * iterations)),
 * n_ij = x_ij / |x_ij| pointing from j to i. Weight 0 switches it off (the caller skips it). */
#ifndef GRAINS_KERNELS_CLUMPING_H
#define GRAINS_KERNELS_CLUMPING_H
#include "mass_shock.h"

/* i's clumping scale: weight x fraction, both with their point attributes */
GR_INLINE float gr_clump_scale(const gr_grains* g, const gr_params* prm, int i) {
  float k = prm->clumping_stiffness * gr_attr(g->attractionstiffness, i);
  float fraction = gr_max(0.0f, gr_min(1.0f, k / prm->stiffness_denominator));
  return prm->clumping_weight * gr_attr(g->attractionweight, i) * fraction;
}

/* correction of i toward j; dist = |x_ij| > 0, n = x_ij / dist, gap = dist - (r_i + r_j) >= 0 */
GR_INLINE gr_float3 gr_clump_pair(gr_float3 n, float gap, float share, float scale) {
  return gr_scale(n, -share * gap * scale);
}

#endif /* GRAINS_KERNELS_CLUMPING_H */
