/* contact_solver gauss_seidel's contacts and its pass over one of them: the CPU sweeps
 * (nodes/grains/gauss_seidel.cpp, which says why, and how the contacts are ordered and carried
 * from substep to substep) and the OpenCL device's (opencl/grains.cl, gr_k_sequential) call the
 * same gr_seq_pass.
 *
 * A contact c between grains i and j (j a plane for colliders) keeps two accumulators over the
 * substep, in metres of relative displacement: ln, the normal correction it applied (>= 0), and
 * lt, the tangential one. A pass over c:
 *   normal:   C = |x_ij| - (r_i + r_j) (planes: (x_i - x_s) . n - r_i);
 *             ln' = max(0, ln - w k C) (it can take back what it pushed, never pull; w is
 *             over_relaxation);
 *             i moves a_i (ln' - ln) n, j moves -a_j (ln' - ln) n, a_i = `share`;
 *   friction: u = the pair's relative displacement over the substep (planes: relative to the
 *             collider's motion), its tangential part u_t; lt' = lt - u_t; unless |lt'| is under
 *             mu_s ln' (static_threshold x friction) it is cut to mu_k ln' (scale_kinetic x
 *             friction; gr_friction, contact.h): Coulomb's law with the normal and tangential
 *             loads of the same contact (Macklin et al. 2014 eqs. 23-25, bounded by the normal
 *             multiplier as Mueller et al. 2020 bound XPBD friction); i moves a_i (lt' - lt), j
 *             the opposite a_j share.
 * k is the repulsion weight x stiffness fraction (1 for colliders, which always hold). A contact
 * without load holds no friction: what it rubbed in the substep is given back. */
#ifndef GRAINS_KERNELS_SEQUENTIAL_H
#define GRAINS_KERNELS_SEQUENTIAL_H
#include "collider.h"
#include "contact.h"
#include "distance.h"
#include "mass_shock.h"

#ifdef GR_OPENCL
typedef ulong gr_ulong;
#else
typedef unsigned long long gr_ulong;
#endif

/* One contact; the host builds them each substep and the device reads the same bytes (56 a
 * contact on both sides: 8-byte key aligned at 16). */
typedef struct {
  int i, j; /* j < 0: collider plane entry e */
  gr_uint e;
  gr_uint moves; /* bit 0: i moves (mass > 0), bit 1: j does (a fixed grain is never written);
                  * bit 2: i's id is above j's when the list was built (a load is carried
                  * from the lower id's side, gr_seq_stored_lt) */
  gr_ulong key;  /* who the contact is across substeps (the grains' ids; a plane: its collider) */
  float k;       /* correction scale (repulsion weight x stiffness fraction; planes 1) */
  float share;   /* i's share of a correction, w_i / (w_i + w_j) (planes 1); j takes the rest */
  float mu;      /* friction scale (friction_with_particles or _colliders x the attribute) */
  float ln;      /* normal correction applied in the substep (m of relative motion) */
  float lt[3];   /* tangential correction applied in the substep (m), i's side */
} gr_seq_contact;

/* a[i] += d s */
GR_HOT void gr_seq_move(GR_GLOBAL float* a, int i, gr_float3 d, float s) {
  gr_store3(a, i, gr_madd(gr_load3(a, i), d, s));
}

/* d applied to the contact's grains by their shares; a fixed grain's share is 0 (its partner's
 * 1): it is read, never written, so that blocks swept at once may share it */
GR_INLINE void gr_seq_apply(GR_GLOBAL float* p, const GR_GLOBAL gr_seq_contact* q, gr_float3 d) {
  if (q->moves & 1u) gr_seq_move(p, q->i, d, q->share);
  if (q->moves & 2u) gr_seq_move(p, q->j, d, -(1.0f - q->share));
}

/* the contact's normal from i's side into *nrm, and its gap C (< 0: overlap), at positions x */
GR_INLINE float gr_seq_geometry(const gr_grains* g, const GR_GLOBAL float* x,
                                const GR_GLOBAL gr_seq_contact* q, gr_float3* nrm) {
  gr_float3 d;
  float dist;
  if (q->j < 0) {
    *nrm = gr_plane_normal(g, q->e);
    return -gr_plane_penetration(g, q->i, q->e, gr_load3(x, q->i));
  }
  d = gr_sub(gr_load3(x, q->i), gr_load3(x, q->j));
  dist = gr_length(d);
  *nrm = gr_pair_normal(d, dist, q->i, q->j);
  return dist - g->radius[q->i] - g->radius[q->j];
}

/* a grain pair apart at positions x, found without a square root: most of the search's
 * candidates (in a settled packing two of three) never touch in the substep */
GR_INLINE int gr_seq_apart(const gr_grains* g, const GR_GLOBAL float* x,
                           const GR_GLOBAL gr_seq_contact* q) {
  gr_float3 d;
  float reach;
  if (q->j < 0) return 0;
  d = gr_sub(gr_load3(x, q->i), gr_load3(x, q->j));
  reach = g->radius[q->i] + g->radius[q->j];
  return gr_dot(d, d) >= reach * reach;
}

/* one pass over contact q at positions p (in place), g->P the substep's start; `relax` is
 * over_relaxation */
GR_INLINE void gr_seq_pass(const gr_grains* g, const gr_params* prm, GR_GLOBAL float* p,
                           GR_GLOBAL gr_seq_contact* q, float relax) {
  gr_float3 nrm, dn, u, lt0, lt;
  float C, ln;
  if (!(q->ln > 0.0f) && gr_seq_apart(g, p, q)) return;
  C = gr_seq_geometry(g, p, q, &nrm);
  if (C >= 0.0f && !(q->ln > 0.0f)) return;
  ln = gr_max(0.0f, q->ln - relax * q->k * C);
  dn = gr_scale(nrm, ln - q->ln);
  q->ln = ln;
  gr_seq_apply(p, q, dn);
  if (!(ln > 0.0f) || !(q->mu > 0.0f)) {
    /* the cone of a zero normal load is a point: what the contact rubbed is given back */
    if (q->lt[0] != 0.0f || q->lt[1] != 0.0f || q->lt[2] != 0.0f) {
      const gr_float3 back = gr_make3(-q->lt[0], -q->lt[1], -q->lt[2]);
      q->lt[0] = q->lt[1] = q->lt[2] = 0.0f;
      gr_seq_apply(p, q, back);
    }
    return;
  }
  u = gr_sub(gr_load3(p, q->i), gr_load3(g->P, q->i));
  if (q->j >= 0) {
    u = gr_sub(u, gr_sub(gr_load3(p, q->j), gr_load3(g->P, q->j)));
  } else {
    const GR_GLOBAL float* pl = g->plane + 9 * q->e;
    u = gr_sub(u, gr_scale(gr_make3(pl[6], pl[7], pl[8]), prm->dt));
  }
  lt0 = gr_make3(q->lt[0], q->lt[1], q->lt[2]);
  /* the substep's tangential correction so far must cancel its slip, within the contact's cone
   * (static below static_threshold x mu ln, else cut to scale_kinetic x it) */
  lt = gr_friction(gr_sub(u, lt0), nrm, q->mu * ln, prm->static_threshold, prm->scale_kinetic);
  q->lt[0] = lt.x;
  q->lt[1] = lt.y;
  q->lt[2] = lt.z;
  gr_seq_apply(p, q, gr_sub(lt, lt0));
}

/* a contact of a list kept from the last substep (gauss_seidel.cpp) starts with the load it
 * ended with when there is a warm start and a normal load, scaled by `scale` ((dt / dt_last)^2: a
 * position-level load is a force x dt^2), else with none. Returns whether it carries a load. */
GR_INLINE int gr_seq_keep(GR_GLOBAL gr_seq_contact* q, int warm, float scale) {
  gr_float3 t;
  if (!warm || !(q->ln > 0.0f)) {
    q->ln = 0.0f;
    q->lt[0] = q->lt[1] = q->lt[2] = 0.0f;
    return 0;
  }
  q->ln *= scale;
  t = gr_scale(gr_make3(q->lt[0], q->lt[1], q->lt[2]), scale);
  q->lt[0] = t.x;
  q->lt[1] = t.y;
  q->lt[2] = t.z;
  return 1;
}

/* pre-stabilization of contact q (Macklin et al. 2014 sec. 4.4; gauss_seidel.cpp says when it
 * runs and why): the overlap at the start positions x removed from x and from the predicted
 * positions p alike, without velocity or friction. `carried`, when not null, collects what the
 * contact moved each grain (a contact that carried a load). Returns the move over i's radius,
 * the measure the passes stop on. */
GR_INLINE float gr_seq_stabilize(const gr_grains* g, GR_GLOBAL float* x, GR_GLOBAL float* p,
                                 GR_GLOBAL float* carried, const GR_GLOBAL gr_seq_contact* q) {
  gr_float3 nrm, d;
  float C;
  if (gr_seq_apart(g, x, q)) return 0.0f;
  C = gr_seq_geometry(g, x, q, &nrm);
  if (!(C < 0.0f)) return 0.0f;
  d = gr_scale(nrm, -q->k * C);
  if (q->moves & 1u) {
    gr_seq_move(x, q->i, d, q->share);
    gr_seq_move(p, q->i, d, q->share);
    if (carried) gr_seq_move(carried, q->i, d, q->share);
  }
  if (q->moves & 2u) {
    gr_seq_move(x, q->j, d, -(1.0f - q->share));
    gr_seq_move(p, q->j, d, -(1.0f - q->share));
    if (carried) gr_seq_move(carried, q->j, d, -(1.0f - q->share));
  }
  return -q->k * C / g->radius[q->i];
}

/* the key of a plane contact: its grain's id, then the collider and how many of the grain's
 * planes of that collider came before it (a box's corner: up to 3) */
#define GR_SEQ_PLANE_KEY 0x80000000u

/* Grain i's contacts, in the list's order (the host builds the list grain by grain in
 * gauss_seidel.cpp, a device likewise in gr_k_seq_fill): a pair with each grain j > i of i's
 * row when one of them moves, the pair is not mutually constrained (unless such pairs collide)
 * and its repulsion scale is positive; then, when i moves, one contact with each of i's
 * collider plane entries (plane_collider: each entry's collider). id: the grains' ids (null:
 * their indices), which key each contact across substeps. Written from out (null: counted
 * only); returns how many. */
GR_INLINE gr_uint gr_seq_build(const gr_grains* g, const gr_params* prm, const GR_GLOBAL int* id,
                               const GR_GLOBAL int* plane_collider, int i,
                               GR_GLOBAL gr_seq_contact* out) {
  const float wi = g->inv_mass[i];
  const gr_uint a = (gr_uint)(id ? id[i] : i);
  const int pairs = g->nbr_offsets && prm->internal_collisions_weight > 0.0f;
  const int skip_constrained =
      g->con_offsets && !prm->collide_mutually_constrained_particles && !g->nbr_unconstrained;
  gr_uint count = 0, e, f;
  gr_seq_contact q;
  if (pairs) {
    const float ki = gr_repulsion_scale(g, prm, i);
    for (e = g->nbr_offsets[i]; e < g->nbr_offsets[i + 1]; ++e) {
      const int j = (int)g->nbr_indices[e];
      float wj, k;
      gr_uint b;
      if (j <= i) continue;
      wj = g->inv_mass[j];
      if (!(wi + wj > 0.0f)) continue;
      if (skip_constrained && gr_constrained(g, i, j)) continue;
      k = 0.5f * (ki + gr_repulsion_scale(g, prm, j));
      if (!(k > 0.0f)) continue;
      if (out) {
        b = (gr_uint)(id ? id[j] : j);
        q.i = i;
        q.j = j;
        q.e = 0u;
        q.moves = (wi > 0.0f ? 1u : 0u) | (wj > 0.0f ? 2u : 0u) | (a > b ? 4u : 0u);
        q.key = ((gr_ulong)(a < b ? a : b) << 32) | (gr_ulong)(a < b ? b : a);
        q.k = k;
        q.share = prm->mass_shock == 2 ? gr_pair_share(g, prm, i, j) : wi / (wi + wj);
        q.mu = prm->friction_with_particles * 0.5f *
               (gr_attr(g->friction, i) + gr_attr(g->friction, j));
        q.ln = 0.0f;
        q.lt[0] = q.lt[1] = q.lt[2] = 0.0f;
        out[count] = q;
      }
      ++count;
    }
  }
  if (g->plane_offsets && wi > 0.0f) {
    const gr_uint first = g->plane_offsets[i];
    for (e = first; e < g->plane_offsets[i + 1]; ++e) {
      const int collider = plane_collider[e];
      gr_uint seen = 0;
      for (f = first; f < e; ++f) seen += plane_collider[f] == collider ? 1u : 0u;
      if (out) {
        q.i = i;
        q.j = -1;
        q.e = e;
        q.moves = 1u;
        q.key = ((gr_ulong)a << 32) |
                (gr_ulong)(GR_SEQ_PLANE_KEY | ((gr_uint)collider << 2) | (seen < 3u ? seen : 3u));
        q.k = 1.0f;
        q.share = 1.0f;
        q.mu = prm->friction_with_colliders * gr_attr(g->friction, i);
        q.ln = 0.0f;
        q.lt[0] = q.lt[1] = q.lt[2] = 0.0f;
        out[count] = q;
      }
      ++count;
    }
  }
  return count;
}

/* a contact's tangential load as it is carried to the next substep: from the side of the
 * grain with the lower id (bit 2 of moves), so that the next list, whose i may be the other
 * grain, finds it by key whatever order the grains come in */
GR_INLINE float gr_seq_carry_sign(const GR_GLOBAL gr_seq_contact* q) {
  return (q->moves & 4u) ? -1.0f : 1.0f;
}

/* the number of trailing zero bits of x != 0 */
GR_INLINE gr_uint gr_ctz64(gr_ulong x) {
#ifdef GR_OPENCL
  return (gr_uint)(63 - clz(x & (~x + 1)));
#else
  return (gr_uint)__builtin_ctzll(x);
#endif
}

/* Contact q's wave in its block (GrainsSolver::order_waves, a device's gr_k_seq_waves): the
 * first none of its moving grains is in yet, marked for them in `mark` (two words a grain: waves
 * 0-127, a bit each). A grain in all 128 gives the contact a wave of its own, the next of
 * *beyond (128 at the block's start): no mark needed. */
GR_INLINE gr_uint gr_seq_wave(GR_GLOBAL gr_ulong* mark, const GR_GLOBAL gr_seq_contact* q,
                              gr_uint* beyond) {
  gr_ulong in0 = 0, in1 = 0;
  gr_uint w;
  int h;
  for (h = 0; h < 2; ++h) {
    if (q->moves & (1u << h)) {
      const gr_ulong x = 2 * (gr_ulong)(h ? q->j : q->i);
      in0 |= mark[x];
      in1 |= mark[x + 1];
    }
  }
  if (~in0)
    w = gr_ctz64(~in0);
  else if (~in1)
    w = 64u + gr_ctz64(~in1);
  else
    w = (*beyond)++;
  if (w < 128u)
    for (h = 0; h < 2; ++h)
      if (q->moves & (1u << h))
        mark[2 * (gr_ulong)(h ? q->j : q->i) + (w >> 6)] |= (gr_ulong)1 << (w & 63u);
  return w;
}

/* the slot of the open-addressed table of 2^bits slots (bits >= 1) where key's search starts */
GR_INLINE gr_uint gr_seq_slot(gr_ulong key, int bits) {
  return (gr_uint)((key * (gr_ulong)0x9E3779B97F4A7C15UL) >> (64 - bits));
}

/* contact q starts with the load carried under its key (ln and the lower id's side's lt,
 * gr_seq_carry_sign), scaled by `scale` ((dt / dt_last)^2) */
GR_INLINE void gr_seq_take_load(GR_GLOBAL gr_seq_contact* q, float ln, gr_float3 lt, float scale) {
  const gr_float3 t = gr_scale(lt, gr_seq_carry_sign(q) * scale);
  q->ln = ln * scale;
  q->lt[0] = t.x;
  q->lt[1] = t.y;
  q->lt[2] = t.z;
}

#endif /* GRAINS_KERNELS_SEQUENTIAL_H */
