/* Pins (help page "Targets (Pins)"; DESIGN §4): grain i is pulled toward its `targetP`,
 *   dp_i = (targetP_i - p_i) * target_weight * targetweight_i
 *          * min(1, target_stiffness * targetstiffness_i / (substeps * iterations)),
 * gathered with the other corrections of the Jacobi iteration (one count when nonzero). The
 * fraction is the per-iteration share of the remaining distance, so a lone pinned grain keeps
 * (1 - f)^iterations of its distance to the target after a substep. A missing `targetstiffness`
 * attribute means no pin at all (help page): the caller leaves g->targetP null then. */
#ifndef GRAINS_KERNELS_PIN_H
#define GRAINS_KERNELS_PIN_H
#include "params.h"

/* i's pin scale: weight x stiffness fraction, both with their point attributes */
GR_INLINE float gr_pin_scale(const gr_grains* g, const gr_params* prm, int i) {
  float k = prm->target_stiffness * g->targetstiffness[i];
  float fraction = gr_max(0.0f, gr_min(1.0f, k / prm->stiffness_denominator));
  return prm->target_weight * gr_attr(g->targetweight, i) * fraction;
}

/* Adds i's pin correction to *sum; returns 1 when it produced a correction. */
GR_INLINE int gr_gather_pin(const gr_grains* g, const gr_params* prm, const GR_GLOBAL float* p,
                            int i, gr_float3* sum) {
  float scale = gr_pin_scale(g, prm, i);
  if (!(scale > 0.0f)) return 0;
  gr_float3 d = gr_sub(gr_load3(g->targetP, i), gr_load3(p, i));
  if (d.x == 0.0f && d.y == 0.0f && d.z == 0.0f) return 0;
  *sum = gr_madd(*sum, d, scale);
  return 1;
}

#endif /* GRAINS_KERNELS_PIN_H */
