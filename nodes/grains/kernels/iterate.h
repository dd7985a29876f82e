/* One Jacobi iteration of grain i (DESIGN §4 step 3; Macklin et al. 2014 §4.2 eq. 12):
 *   p_i' = p_i + over_relaxation / n_i * sum_c dp_i,c,
 * n_i = the number of constraints that produced a nonzero correction (1 when
 * disable_constraint_averaging). Each grain reads the previous iterate of its neighbours and
 * writes only its own next iterate (and its own rows of the overlap accumulators): gather, no
 * atomics, the same for any thread count. */
#ifndef GRAINS_KERNELS_ITERATE_H
#define GRAINS_KERNELS_ITERATE_H
#include "collider.h"
#include "pin.h"

/* Accumulated contact corrections for the friction pass (gr_friction_pass); all null when not
 * needed. */
typedef struct {
  GR_GLOBAL float* pair_iteration; /* (row length) overlap this iteration: the caller's
                                    * scratch for the grain being iterated (per thread) */
  /* (neighbour entries) sum over iterations of overlap / n_i, as float bits: unsigned storage,
   * so that the solver can lend the same memory to the neighbour search between substeps */
  GR_GLOBAL gr_uint* pair;
  GR_GLOBAL float* collider;       /* (plane entries) the same for the collider planes */
  /* (n x GR_MAX_PLANES x 3) m: each collider plane's share of i's applied corrections, summed
   * over the iterations (impact data and collision feedback), or null. The collider part of a
   * grain's corrections is split among its planes in proportion to their overlaps (exact for
   * one plane, the common case). */
  GR_GLOBAL float* collider_dx;
  /* (n x 3) m: the friction each grain received so far in the substep (accurate friction); null
   * when the friction pass runs once */
  GR_GLOBAL float* friction_dx;
} gr_normal_sums;

GR_INLINE gr_float3 gr_average(gr_float3 p, gr_float3 sum, int count, float omega,
                               int disable_averaging) {
  if (count == 0) return p;
  return gr_madd(p, sum, disable_averaging ? omega : omega / (float)count);
}

/* Chebyshev semi-iterative acceleration of the Jacobi iterations (Wang 2015, "A Chebyshev
 * Semi-Iterative Approach for Accelerating Projective and Position-based Dynamics"). With rho an
 * estimate of the spectral radius of the iteration, iteration k's Jacobi result x^ is taken from
 * the iterate before the previous one:
 *   x_{k+1} = x_{k-1} + omega_k (x^ - x_{k-1}),
 * omega_k = 1 for the first GR_CHEBYSHEV_DELAY iterations (plain Jacobi while the contacts of
 * the substep appear), then 2 / (2 - rho^2), then 4 / (4 - rho^2 omega_{k-1}), which falls
 * towards 2 / (1 + sqrt(1 - rho^2)). The slow, smooth modes of a pile or a chain (a correction
 * that has to travel many grains) then decay like ((1 - sqrt(1 - rho^2)) / rho)^k instead of
 * rho^k when rho matches the iteration. Contacts make the iteration nonlinear: a rho above the
 * true radius overshoots and can diverge. */
#define GR_CHEBYSHEV_DELAY 5
GR_INLINE float gr_chebyshev_omega(int iteration, float rho, float previous) {
  if (iteration < GR_CHEBYSHEV_DELAY) return 1.0f;
  if (iteration == GR_CHEBYSHEV_DELAY) return 2.0f / (2.0f - rho * rho);
  return 4.0f / (4.0f - rho * rho * previous);
}

/* (fused, gr_fmadd: the host's step and a device's make the same floats) */
GR_INLINE gr_float3 gr_chebyshev(gr_float3 x_hat, gr_float3 x_before, float omega) {
  return gr_fmadd(x_before, gr_sub(x_hat, x_before), omega);
}

/* the factor the averaged sum is applied with */
GR_INLINE float gr_average_factor(int count, float omega, int disable_averaging) {
  if (count == 0) return 0.0f;
  return disable_averaging ? omega : omega / (float)count;
}

/* adds the applied collider correction csum * f to i's planes, split by the weights w[k] */
GR_INLINE void gr_add_collider_dx(GR_GLOBAL float* collider_dx, int i, gr_float3 csum, float f,
                                  const float* w) {
  float total = 0.0f;
  int k;
  for (k = 0; k < GR_MAX_PLANES; ++k) total += w[k];
  if (!(total > 0.0f)) return;
  for (k = 0; k < GR_MAX_PLANES; ++k) {
    if (!(w[k] > 0.0f)) continue;
    int slot = GR_MAX_PLANES * i + k;
    gr_store3(collider_dx, slot, gr_madd(gr_load3(collider_dx, slot), csum, f * w[k] / total));
  }
}

/* constraint loop: contacts, clumping, collider planes,
 * explicit constraints, pins */
GR_INLINE gr_float3 gr_iterate(const gr_grains* g, const gr_params* prm, const GR_GLOBAL float* p,
                               int i, const gr_normal_sums* acc) {
  /* acc->pair_iteration is row scratch, read back below; acc->pair is per neighbour entry */
  gr_float3 sum = gr_make3(0.0f, 0.0f, 0.0f);
  gr_float3 csum = gr_make3(0.0f, 0.0f, 0.0f);
  int count = 0, ccount = 0;
  float pen[GR_MAX_PLANES];
  if (g->nbr_offsets) count += gr_gather_pairs(g, prm, p, i, acc->pair_iteration, &sum);
  if (g->plane_offsets) ccount = gr_gather_collider(g, prm, p, i, pen, &csum);
  count += ccount;
  sum = gr_add(sum, csum);
  if (g->con_offsets) count += gr_gather_constraints(g, prm, p, i, &sum);
  if (acc->collider_dx && ccount)
    gr_add_collider_dx(acc->collider_dx, i, csum,
                       gr_average_factor(count, prm->over_relaxation, prm->disable_constraint_averaging), pen);
  if (acc->pair || acc->collider) {
    float share = (prm->disable_constraint_averaging || count == 0) ? 1.0f : 1.0f / (float)count;
    if (acc->pair && g->nbr_offsets) {
      gr_uint k;
      /* bounds read once: the stores below could otherwise alias them, and the loop would not
       * vectorise */
      const gr_uint b = g->nbr_offsets[i], e = g->nbr_offsets[i + 1];
      /* in the contact loop's blocks of GR_LANES, the stores the scratch row was just written
       * with: the compiler's loop read it 16 floats at a time from where the sums' alignment put
       * it, so each load spanned two of those stores and waited for them to reach the cache */
      for (k = b; k + GR_LANES <= e; k += GR_LANES)
        gr_add_block(acc->pair + k, acc->pair_iteration + (k - b), share);
      for (; k < e; ++k)
        acc->pair[k] = gr_as_uint(gr_as_float(acc->pair[k]) + acc->pair_iteration[k - b] * share);
    }
    if (acc->collider && g->plane_offsets) {
      const gr_uint b = g->plane_offsets[i], e = g->plane_offsets[i + 1];
      gr_uint k;
      for (k = b; k < e; ++k) acc->collider[k] += pen[k - b] * share;
    }
  }
  return gr_average(gr_load3(p, i), sum, count, prm->over_relaxation, prm->disable_constraint_averaging);
}

/* Pre-stabilization (Macklin et al. 2014 §4.4): one Jacobi iteration of the contacts alone
 * (grain pairs and collider planes, averaged, no friction) on the start-of-substep positions x.
 * The solver moves both the start and the predicted position of each grain by the result, so
 * overlap left from earlier substeps or made by emission is removed without turning into
 * velocity: resolved inside a substep, an overlap d becomes a speed d / dt, which grows as the
 * substeps shrink. prm must have clumping off. */
GR_INLINE gr_float3 gr_stabilize(const gr_grains* g, const gr_params* prm,
                                 const GR_GLOBAL float* x, int i) {
  gr_float3 sum = gr_make3(0.0f, 0.0f, 0.0f);
  int count = 0;
  float pen[GR_MAX_PLANES];
  if (g->nbr_offsets) count += gr_gather_pairs(g, prm, x, i, 0, &sum);
  if (g->plane_offsets) count += gr_gather_collider(g, prm, x, i, pen, &sum);
  return gr_average(gr_load3(x, i), sum, count, 1.0f, prm->disable_constraint_averaging);
}

/* Friction of grain i (DESIGN §4 "friction"; Macklin et al. 2014 eqs. 23-25, bounded as XPBD
 * bounds friction by the normal multiplier, Mueller et al. 2020), over all its contacts at once,
 * each contact's slip s_c weighing it (gr_slip_sums):
 *   t = sum sl_c (-share_c s_c) / sum sl_c: the slip the grain must lose to move with what it
 *       touches; contacts that slip alike (a grain resting on three) agree on it, and contacts
 *       that move with the grain (its neighbours in a sliding block) hardly count;
 *   B = sum sl_c mu_c share_c a_c / max sl_c: the Coulomb bound, the normal corrections a_c the
 *       slipping contacts applied in the substep times their friction, summed, not averaged;
 *   F = the friction the grain already received in the substep (accurate friction: the pass
 *       runs after every iteration; otherwise once after the loop, F = 0):
 *   |t + F| <= static_threshold B: apply t (static);
 *   otherwise apply t min(1, max(0, scale_kinetic B - |F|) / |t|) (kinetic: the substep's
 *   friction totals scale_kinetic B).
 * The bound grows with the normal corrections, which scale with the same dt^2 as the slip, so
 * sticking does not depend on the substep or iteration counts, nor on how many contacts share
 * the load. With disable_constraint_averaging t is the plain sum of the removals, so equal and
 * opposite pair frictions keep momentum. Not over-relaxed. */
GR_INLINE gr_float3 gr_friction_pass(const gr_grains* g, const gr_params* prm,
                                     const GR_GLOBAL float* p, const gr_normal_sums* acc, int i) {
  gr_slip_sums f;
  gr_slip_sums c;
  float w[GR_MAX_PLANES];
  f.target = gr_make3(0.0f, 0.0f, 0.0f);
  f.plain = f.target;
  f.weight = f.bound = f.largest = 0.0f;
  c = f;
  const gr_float3 pi = gr_load3(p, i);
  if (acc->pair && g->nbr_offsets) gr_gather_pair_slip(g, prm, p, acc->pair, i, &f);
  if (acc->collider && g->plane_offsets)
    gr_gather_collider_slip(g, prm, p, acc->collider + g->plane_offsets[i], i, &c, w);
  const float weight = f.weight + c.weight;
  const float largest = gr_max(f.largest, c.largest);
  if (!(weight > 0.0f) || !(largest > 0.0f)) return pi;
  const float bound = (f.bound + c.bound) / largest;
  gr_float3 t = prm->disable_constraint_averaging ? gr_add(f.plain, c.plain)
                                       : gr_scale(gr_add(f.target, c.target), 1.0f / weight);
  const float tl = gr_length(t);
  if (!(tl > 0.0f) || !(bound > 0.0f)) return pi;
  gr_float3 F = acc->friction_dx ? gr_load3(acc->friction_dx, i) : gr_make3(0.0f, 0.0f, 0.0f);
  float frac = 1.0f;
  if (!(gr_length(gr_add(t, F)) <= prm->static_threshold * bound))
    frac = gr_min(1.0f, gr_max(0.0f, prm->scale_kinetic * bound - gr_length(F)) / tl);
  const gr_float3 applied = gr_scale(t, frac);
  if (acc->friction_dx) gr_store3(acc->friction_dx, i, gr_add(F, applied));
  /* the colliders' part, for impact data: their share of the bound */
  if (acc->collider_dx && c.bound > 0.0f)
    gr_add_collider_dx(acc->collider_dx, i, applied, c.bound / (f.bound + c.bound), w);
  return gr_add(pi, applied);
}

#endif /* GRAINS_KERNELS_ITERATE_H */
