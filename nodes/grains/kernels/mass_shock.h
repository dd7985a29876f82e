/* Mass-shock scaling (help page "Enable Mass-Shock Scaling"; Macklin et al. 2014 §5.2 eq. 21,
 * m*_i = m_i exp(-k h_i)): grains higher along the shock axis are made lighter so a stack's
 * corrections move the upper grain of each pair more and piles converge in fewer iterations.
 *   global: shockmass_i = mass_i * exp(-0.15 * power * h_i / separation),
 *           h_i = (P_i - shock_origin) . shock_axis, exponent clamped to +-80 (float range);
 *   local:  the pair's relative scale exp(-0.15 * min(power, 7) * (h_i - h_j) / separation)
 *           is applied to i's mass on the fly (no attribute read or written).
 * A power of 1 gives a 15% ratio between two grains stacked one separation apart. */
#ifndef GRAINS_KERNELS_MASS_SHOCK_H
#define GRAINS_KERNELS_MASS_SHOCK_H
#include "params.h"

#define GR_SHOCK_EXP_LIMIT 80.0f

GR_INLINE float gr_shock_height(const gr_params* prm, gr_float3 P) {
  return (P.x - prm->shock_origin_x) * prm->shock_axis_x +
         (P.y - prm->shock_origin_y) * prm->shock_axis_y +
         (P.z - prm->shock_origin_z) * prm->shock_axis_z;
}

/* exp(-0.15 * power * dh / separation), exponent clamped */
GR_INLINE float gr_shock_scale(const gr_params* prm, float dh) {
  float e = -0.15f * prm->shock_power * dh * prm->shock_inv_separation;
  e = gr_max(-GR_SHOCK_EXP_LIMIT, gr_min(GR_SHOCK_EXP_LIMIT, e));
  return gr_exp(e);
}

/* global: the virtual mass of grain i, written to `shockmass` before iterating */
GR_INLINE float gr_shockmass(const gr_params* prm, float mass, gr_float3 P) {
  return mass * gr_shock_scale(prm, gr_shock_height(prm, P));
}

/* i's share w_i / (w_i + w_j) of a pair correction, with the local relative scale if asked;
 * 0 when both grains are immovable */
GR_INLINE float gr_pair_share(const gr_grains* g, const gr_params* prm, int i, int j) {
  float wi = g->inv_mass[i], wj = g->inv_mass[j];
  if (prm->mass_shock == 2) {
    float dh = gr_shock_height(prm, gr_load3(g->P, i)) - gr_shock_height(prm, gr_load3(g->P, j));
    wi /= gr_shock_scale(prm, dh); /* i's mass times the relative scale */
  }
  float s = wi + wj;
  return s > 0.0f ? wi / s : 0.0f;
}

/* the share without mass-shock (clumping is not a stacking constraint) */
GR_INLINE float gr_plain_share(const gr_grains* g, int i, int j) {
  float wi = g->mass[i] > 0.0f ? 1.0f / g->mass[i] : 0.0f;
  float wj = g->mass[j] > 0.0f ? 1.0f / g->mass[j] : 0.0f;
  float s = wi + wj;
  return s > 0.0f ? wi / s : 0.0f;
}

#endif /* GRAINS_KERNELS_MASS_SHOCK_H */
