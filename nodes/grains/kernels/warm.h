/* contact_solver gauss_seidel's warm start, step by step, and the velocity its
 * pre-stabilization takes back (gauss_seidel.cpp gives the formulas and says why; the CPU path
 * and the OpenCL device, grains.cl, call these). A contact k's repeated load waits in its own
 * accumulators (q->ln, q->lt) with its normal normal[3k..] and its factor factor[k]; repeat (n x 3)
 * is what the loads, each scaled by its factor, give every moving grain (D); external (n x 3)
 * each grain's external step G over the substep. The comparisons are written as std::min,
 * std::max and std::clamp make them, so that both sides agree on NaN. */
#ifndef GRAINS_KERNELS_WARM_H
#define GRAINS_KERNELS_WARM_H
#include "sequential.h"

/* the most a warm start may throw a grain off balance beyond its external step, in radii, and
 * the most of that it may lift the grain against it */
#define GR_WARM_SLACK 0.1f
#define GR_WARM_LIFT 0.05f

/* contact q's carried load (q->ln, q->lt as carried over, already scaled to this substep): the
 * tangential part kept across the contact's normal at p (written to normal); returns the
 * contact's factor, 1 when it carries a normal load, else 0 */
GR_INLINE float gr_warm_open(const gr_grains* g, const GR_GLOBAL float* p, GR_GLOBAL gr_seq_contact* q,
                             GR_GLOBAL float* normal) {
  gr_float3 nrm, t = gr_make3(q->lt[0], q->lt[1], q->lt[2]);
  gr_seq_geometry(g, p, q, &nrm);
  t = gr_madd(t, nrm, -gr_dot(t, nrm));
  q->lt[0] = t.x;
  q->lt[1] = t.y;
  q->lt[2] = t.z;
  normal[0] = nrm.x;
  normal[1] = nrm.y;
  normal[2] = nrm.z;
  return q->ln > 0.0f ? 1.0f : 0.0f;
}

/* contact q's load, scaled by its factor, added to what its grains receive (repeat) */
GR_INLINE void gr_warm_repeat(const GR_GLOBAL gr_seq_contact* q, const GR_GLOBAL float* normal,
                              float factor, GR_GLOBAL float* repeat) {
  gr_float3 d;
  if (!(factor > 0.0f)) return;
  d = gr_scale(gr_add(gr_scale(gr_make3(normal[0], normal[1], normal[2]), q->ln),
                      gr_make3(q->lt[0], q->lt[1], q->lt[2])),
               factor);
  if (q->moves & 1u) gr_store3(repeat, q->i, gr_add(gr_load3(repeat, q->i), gr_scale(d, q->share)));
  if (q->moves & 2u)
    gr_store3(repeat, q->j, gr_sub(gr_load3(repeat, q->j), gr_scale(d, 1.0f - q->share)));
}

/* grain i's balance: the factor in [0, 1] that brings its repeated loads' displacement D nearest
 * -G, G = p - P - dt v its external step (written to external; zero for a fixed grain, whose
 * balance is 1: it takes any load) */
GR_INLINE float gr_warm_balance(const gr_grains* g, const GR_GLOBAL float* p, float dt,
                                const GR_GLOBAL float* repeat, int i, GR_GLOBAL float* external) {
  gr_float3 G, D;
  float dd, b;
  if (!(g->inv_mass[i] > 0.0f)) {
    gr_store3(external, i, gr_make3(0.0f, 0.0f, 0.0f));
    return 1.0f;
  }
  G = gr_sub(gr_sub(gr_load3(p, i), gr_load3(g->P, i)), gr_scale(gr_load3(g->v, i), dt));
  gr_store3(external, i, G);
  D = gr_load3(repeat, i);
  dd = gr_dot(D, D);
  if (!(gr_dot(G, G) > 0.0f && dd > 0.0f)) return 0.0f;
  b = -gr_dot(D, G) / dd;
  return b < 0.0f ? 0.0f : (1.0f < b ? 1.0f : b);
}

/* a contact's factor: the smaller balance of its grains (a plane's: its grain's) */
GR_INLINE float gr_warm_factor(const GR_GLOBAL gr_seq_contact* q, const GR_GLOBAL float* balance) {
  if (q->j < 0) return balance[q->i];
  return balance[q->j] < balance[q->i] ? balance[q->j] : balance[q->i];
}

/* 1 when the scaled loads throw moving grain i off balance by more than a cold start would or
 * a tenth of its radius, |D' + G| > max(|G|, r / 10), or lift it against G by more than r / 20 */
GR_INLINE int gr_warm_cold(const gr_grains* g, const GR_GLOBAL float* repeat,
                           const GR_GLOBAL float* external, int i) {
  const gr_float3 G = gr_load3(external, i);
  const gr_float3 off = gr_add(gr_load3(repeat, i), G); /* D' + G */
  const float el = gr_length(G);
  const float lift = el > 0.0f ? -gr_dot(off, G) / el : 0.0f;
  const float slack = GR_WARM_SLACK * g->radius[i];
  return g->inv_mass[i] > 0.0f &&
         (gr_length(off) > (el < slack ? slack : el) || lift > GR_WARM_LIFT * g->radius[i]);
}

/* the warm start's last sweep: contact q's load scaled by its factor and applied to p (a factor
 * of 0: a cold start) */
GR_INLINE void gr_warm_apply(GR_GLOBAL float* p, GR_GLOBAL gr_seq_contact* q, const GR_GLOBAL float* normal,
                             float factor) {
  gr_float3 t;
  if (!(factor > 0.0f)) {
    q->ln = 0.0f;
    q->lt[0] = q->lt[1] = q->lt[2] = 0.0f;
    return;
  }
  q->ln *= factor;
  t = gr_scale(gr_make3(q->lt[0], q->lt[1], q->lt[2]), factor);
  q->lt[0] = t.x;
  q->lt[1] = t.y;
  q->lt[2] = t.z;
  gr_seq_apply(p, q, gr_add(gr_scale(gr_make3(normal[0], normal[1], normal[2]), q->ln), t));
}

/* The velocity that made the overlap pre-stabilization removed: grain i loses the component of
 * its velocity v against m, what the contacts that carried a load moved it (carried), up to
 * |m| / dt_last; p keeps that velocity's step over dt no more. A grain is never given speed. */
GR_INLINE void gr_warm_take_back(const gr_grains* g, GR_GLOBAL float* v, GR_GLOBAL float* p,
                                 const GR_GLOBAL float* carried, float inv_last, float dt, int i) {
  gr_float3 m, u, vi;
  float length, against, cut;
  if (!(g->inv_mass[i] > 0.0f)) return;
  m = gr_load3(carried, i);
  length = gr_length(m);
  if (!(length > 0.0f)) return;
  u = gr_scale(m, 1.0f / length);
  vi = gr_load3(v, i);
  against = gr_dot(vi, u);
  if (!(against < 0.0f)) return;
  cut = against < -length * inv_last ? -length * inv_last : against; /* <= 0 */
  gr_store3(v, i, gr_madd(vi, u, -cut));
  gr_store3(p, i, gr_madd(gr_load3(p, i), u, -cut * dt));
}

#endif /* GRAINS_KERNELS_WARM_H */
