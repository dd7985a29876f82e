/* Prediction and velocity update (DESIGN §4 steps 1 and 4; help page "Max Speed",
 * "Max Acceleration", "Drift Threshold", "Velocity Blend"; Macklin et al. 2014 Alg. 1).
 *   predict:  v_pred = v + dt * force / mass,  p = P + dt * v_pred;
 *   update:   v_new = (p - P) / dt;  v = (1 - b) v_new + b v_pred        (velocity_blend b);
 *             |v - v_pred| <= max_acceleration * dt  (the change the constraints made);
 *             |v| <= max_speed  (the reported v only; p is kept);
 *             |v| < drift_threshold: the grain stays at P with v = 0. */
#ifndef GRAINS_KERNELS_VELOCITY_H
#define GRAINS_KERNELS_VELOCITY_H
#include "params.h"

GR_INLINE gr_float3 gr_predicted_velocity(const gr_grains* g, const gr_params* prm, int i) {
  gr_float3 v = gr_load3(g->v, i);
  if (g->force && g->mass[i] > 0.0f) {
    const int f = g->force_uniform ? 0 : (g->force_index ? (int)g->force_index[i] : i);
    v = gr_fmadd(v, gr_load3(g->force, f), prm->dt / g->mass[i]);
  }
  return v;
}

/* step 1: the predicted position of grain i */
GR_INLINE void gr_predict(const gr_grains* g, const gr_params* prm, GR_GLOBAL float* p, int i) {
  gr_store3(p, i, gr_fmadd(gr_load3(g->P, i), gr_predicted_velocity(g, prm, i), prm->dt));
}

/* step 4: grain i's end-of-substep position (*P_out) and velocity (*v_out) from the solved p */
GR_INLINE void gr_update_velocity(const gr_grains* g, const gr_params* prm,
                                  const GR_GLOBAL float* p, int i, gr_float3* P_out,
                                  gr_float3* v_out) {
  gr_float3 P = gr_load3(g->P, i);
  gr_float3 x = gr_load3(p, i);
  gr_float3 vp = gr_predicted_velocity(g, prm, i);
  gr_float3 v = gr_scale(gr_sub(x, P), 1.0f / prm->dt);
  float b = prm->velocity_blend;
  if (b != 0.0f) v = gr_add(gr_scale(v, 1.0f - b), gr_scale(vp, b));
  gr_float3 dv = gr_sub(v, vp);
  float dvl = gr_length(dv);
  float dv_max = prm->max_acceleration * prm->dt;
  if (dvl > dv_max) v = gr_madd(vp, dv, dv_max / dvl);
  float speed = gr_length(v);
  if (speed > prm->max_speed) v = gr_scale(v, prm->max_speed / speed);
  if (gr_length(v) < prm->drift_threshold) {
    *P_out = P;
    *v_out = gr_make3(0.0f, 0.0f, 0.0f);
    return;
  }
  *P_out = x;
  *v_out = v;
}

#endif /* GRAINS_KERNELS_VELOCITY_H */
