/* Pins (help page "Targets (Pins)"; DESIGN §4): grain i is pulled toward its `targetP`,
 *   dp_i = (targetP_i - p_i) * target_weight * targetweight_i
 *          * min(1, target_stiffness * targetstiffness_i / (substeps * iterations)),
 * as its own constraint group after each iteration's averaged update (Gauss-Seidel across
 * groups, Jacobi within, like rigid shape matching). Averaged in with the grain's contacts the
 * pull was 1/count of this, so a puppet's pinned interior lagged its target by 9 mm (median,
 * 24 mm at most) where its clumped skin pressed on it. The fraction is the per-iteration share of
 * the remaining distance, so a pinned grain keeps (1 - f)^iterations of its distance to the
 * target after a substep. A missing `targetstiffness` attribute means no pin at all (help
 * page): the caller leaves g->targetP null then. */
#ifndef GRAINS_KERNELS_PIN_H
#define GRAINS_KERNELS_PIN_H
#include "params.h"

/* i's pin scale: weight x stiffness fraction, both with their point attributes */
GR_INLINE float gr_pin_scale(const gr_grains* g, const gr_params* prm, int i) {
  float k = prm->target_stiffness * g->targetstiffness[i];
  float fraction = gr_max(0.0f, gr_min(1.0f, k / prm->stiffness_denominator));
  return prm->target_weight * gr_attr(g->targetweight, i) * fraction;
}

/* Grain i's position after its pin (fused, gr_fmadd: the host's pins and a device's make the
 * same floats). */
GR_INLINE gr_float3 gr_project_pin(const gr_grains* g, const gr_params* prm,
                                   const GR_GLOBAL float* p, int i) {
  const gr_float3 x = gr_load3(p, i);
  const float scale = gr_pin_scale(g, prm, i);
  if (!(scale > 0.0f)) return x;
  return gr_fmadd(x, gr_sub(gr_load3(g->targetP, i), x), scale);
}

#endif /* GRAINS_KERNELS_PIN_H */
