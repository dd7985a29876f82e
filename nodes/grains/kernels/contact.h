/* Grain-grain contact and friction (Macklin, Müller, Chentanez, Kim 2014, "Unified Particle
 * Physics for Real-Time Applications", §6.1; help page "Internal Collisions", "Friction").
 *
 * Contact, eq. 22: C = |x_ij| - (r_i + r_j) >= 0. With overlap d = (r_i + r_j) - |x_ij| > 0 and
 * n = x_ij / |x_ij| (from j to i):
 *   dp_i = w_i / (w_i + w_j) * d * n * internal_collisions_weight * repulsionweight_i
 *          * min(1, internal_collisions_stiffness * repulsionstiffness_i / (substeps * iterations)).
 *
 * Friction, eqs. 23-25: the pair's relative displacement over the substep
 *   dx = (p_i - P_i) - (p_j - P_j), its tangential part, the slip s = dx - (dx . n) n, i's share
 *   w_i / (w_i + w_j); bounded like Coulomb friction by the normal correction the contact applied
 *   in the substep, times the friction scale (friction_with_particles x the `friction`
 *   attribute): static_threshold x scale is the static coefficient, scale_kinetic x scale the
 *   kinetic one. The grain combines its contacts in gr_friction_pass (iterate.h); this file
 *   gathers them (gr_gather_pair_slip). The bound grows with the normal corrections, so soft
 *   contacts, pushed apart over more iterations, rub longer (help page note). */
#ifndef GRAINS_KERNELS_CONTACT_H
#define GRAINS_KERNELS_CONTACT_H
#include "clumping.h"
#include "distance.h"

/* eqs. 23-25: the correction removing slip dx along the plane normal n, bound d (>= 0) */
GR_INLINE gr_float3 gr_friction(gr_float3 dx, gr_float3 n, float bound, float static_threshold,
                                float scale_kinetic) {
  gr_float3 dxt = gr_madd(dx, n, -gr_dot(dx, n));
  float len = gr_length(dxt);
  if (!(len > 0.0f) || !(bound > 0.0f)) return gr_make3(0.0f, 0.0f, 0.0f);
  if (len < static_threshold * bound) return gr_scale(dxt, -1.0f);
  return gr_scale(dxt, -gr_min(1.0f, scale_kinetic * bound / len));
}

/* i's repulsion scale: weight x stiffness fraction, both with their point attributes */
GR_INLINE float gr_repulsion_scale(const gr_grains* g, const gr_params* prm, int i) {
  float k = prm->internal_collisions_stiffness * gr_attr(g->repulsionstiffness, i);
  float fraction = gr_max(0.0f, gr_min(1.0f, k / prm->stiffness_denominator));
  return prm->internal_collisions_weight * gr_attr(g->repulsionweight, i) * fraction;
}

/* the unit direction from j to i; coincident grains separate along +-y by index so the pair
 * still moves apart (deterministically) */
GR_INLINE gr_float3 gr_pair_normal(gr_float3 xij, float dist, int i, int j) {
  if (dist > 0.0f) return gr_scale(xij, 1.0f / dist);
  return gr_make3(0.0f, i < j ? -1.0f : 1.0f, 0.0f);
}

/* the contact loop's lanes: gr_gather_contacts_lanes */
#define GR_LANES 8
/* gr_load_block (prelude.h) loads blocks of exactly 8 */
typedef char gr_lanes_match_load_block[GR_LANES == 8 ? 1 : -1];
/* one block of GR_LANES candidates from entry k: see gr_gather_contacts_lanes. `tail` (a constant
 * at each call): the block may run past the row's end e, so lanes past it repeat entry e - 1
 * and contribute 0; a full block reads its GR_LANES indices as one contiguous run. */
GR_INLINE void gr_contact_block(const gr_grains* g, const GR_GLOBAL float* p, int i, float px,
                                float py, float pz, float ri, float wi, float repulse, gr_uint k,
                                gr_uint e, float* lx, float* ly, float* lz, float* lc, float* ld,
                                const int uniform, const int tail) {
  const GR_GLOBAL gr_uint* nbr = g->nbr_indices;
  int l;
  gr_uint jl[GR_LANES]; /* unsigned: an index widens to an address without a sign extension */
  float qx[GR_LANES], qy[GR_LANES], qz[GR_LANES];
  for (l = 0; l < GR_LANES; ++l) jl[l] = nbr[(tail ? k + (gr_uint)l < e : 1) ? k + (gr_uint)l : e - 1];
  gr_load_block(p, jl, qx, qy, qz);
  /* the partners' radii and inverse masses into lanes before the math, which then reads no
   * memory that `ld` (the caller's row) could alias: with those loads among the math, GCC left
   * the block scalar once ld was that row, and global mass-shock ran 1.7 times slower */
  float rl[GR_LANES], wl[GR_LANES];
  for (l = 0; l < GR_LANES; ++l) {
    rl[l] = uniform ? ri : g->radius[jl[l]];
    wl[l] = uniform ? wi : g->inv_mass[jl[l]];
  }
  for (l = 0; l < GR_LANES; ++l) {
    const int live = tail ? k + (gr_uint)l < e : 1;
    const int j = (int)jl[l];
    const float dx = px - qx[l], dy = py - qy[l], dz = pz - qz[l];
    const float d2 = dx * dx + dy * dy + dz * dz;
    const float rsum = ri + rl[l];
    const float dist = gr_sqrt(d2);
    const float wsum = wi + wl[l];
    const int touching = (d2 < rsum * rsum) & (j != i) & (wsum > 0.0f);
    const float d = touching ? rsum - dist : 0.0f;
    /* correction length share * d * repulse along n = x_ij / dist */
    const float share = uniform ? 0.5f : wi / wsum;
    const float f = (touching & live) ? share * d * repulse : 0.0f;
    const float along = dist > 0.0f ? f / dist : 0.0f;
    const float apart_y = dist > 0.0f ? 0.0f : (i < j ? -f : f);
    lx[l] += along * dx;
    ly[l] += along * dy + apart_y;
    lz[l] += along * dz;
    lc[l] += f != 0.0f ? 1.0f : 0.0f;
    ld[l] = d;
  }
}

/* The common case of gr_gather_pairs: contacts only (no clumping, friction after the loop, no
 * constraint adjacency, no local mass-shock). The same eq. 22 correction, written without
 * branches over blocks of GR_LANES candidates so the compiler turns each block into vector
 * instructions: every candidate is computed, and one that is apart, past the end of the row or
 * i itself contributes 0. Lanes past the end repeat the row's last entry, so the block never
 * reads outside the row. Each lane keeps its own sums, added in lane order at the end: the
 * result depends on the row, not on the thread count. Coincident grains separate along -+y by
 * index, as gr_pair_normal. Shares w_i / (w_i + w_j) with global mass-shock come from inv_mass.
 * `uniform` (a constant at each call, so each call site compiles its own loop): every grain has
 * g->uniform_radius and g->uniform_inv_mass, so the summed radii are 2r and the share
 * w / (w + w) is exactly 1/2, and a candidate costs only its position; the arithmetic is the
 * same, so the result is bit-identical to the general loop's. A block's positions come in
 * through gr_load_block, so p must hold 3 n + 1 floats. overlap_out, when not null, gets whole
 * blocks: it must hold the row's length rounded up to a multiple of GR_LANES. */
GR_HOT int gr_gather_contacts_lanes(const gr_grains* g, const GR_GLOBAL float* p, int i,
                                    float repulse, GR_GLOBAL float* overlap_out, gr_float3* sum,
                                    const int uniform) {
  const float px = p[3 * i], py = p[3 * i + 1], pz = p[3 * i + 2];
  const float ri = uniform ? g->uniform_radius : g->radius[i];
  const float wi = uniform ? g->uniform_inv_mass : g->inv_mass[i];
  const gr_uint b = g->nbr_offsets[i], e = g->nbr_offsets[i + 1];
  float lx[GR_LANES], ly[GR_LANES], lz[GR_LANES], lc[GR_LANES], ld[GR_LANES];
  gr_uint k;
  int l;
  for (l = 0; l < GR_LANES; ++l) lx[l] = ly[l] = lz[l] = lc[l] = 0.0f;
  for (k = b; k < e; k += GR_LANES) {
    /* the block stores its overlaps where they go, as one vector (a copy after it had been
     * 8 scalar moves) */
#ifdef GR_OPENCL
    /* OpenCL C 1.2 has no generic address space: the block writes private lanes, copied out */
    float* out = ld;
#else
    float* out = overlap_out ? overlap_out + (k - b) : ld;
#endif
    if (k + GR_LANES <= e)
      gr_contact_block(g, p, i, px, py, pz, ri, wi, repulse, k, e, lx, ly, lz, lc, out, uniform, 0);
    else
      gr_contact_block(g, p, i, px, py, pz, ri, wi, repulse, k, e, lx, ly, lz, lc, out, uniform, 1);
#ifdef GR_OPENCL
    if (overlap_out)
      for (l = 0; l < GR_LANES; ++l) overlap_out[k - b + (gr_uint)l] = ld[l];
#endif
  }
#ifdef GR_HAVE_SUM_LANES
  {
    float s[4];
    gr_sum_lanes(lx, ly, lz, lc, s);
    sum->x += s[0];
    sum->y += s[1];
    sum->z += s[2];
    return (int)s[3];
  }
#else
  {
    float sx = 0.0f, sy = 0.0f, sz = 0.0f, count = 0.0f;
    for (l = 0; l < GR_LANES; ++l) {
      sx += lx[l];
      sy += ly[l];
      sz += lz[l];
      count += lc[l];
    }
    sum->x += sx;
    sum->y += sy;
    sum->z += sz;
    return (int)count;
  }
#endif
}

/* One Jacobi iteration's pair corrections of grain i (contacts, with friction when
 * clumping; friction is gr_friction_pass's), read from the iterate p. Adds to *sum, returns how many
 * constraints produced a nonzero correction. When `overlap_out` is not null, overlap_out[k] receives
 * the contact overlap seen this iteration with the k-th entry of i's neighbour row (0: none).
 * Most candidates are apart: they are rejected on the squared distance, before any square root,
 * division or attribute read. */
GR_HOT int gr_gather_pairs(const gr_grains* g, const gr_params* prm, const GR_GLOBAL float* p,
                              int i, GR_GLOBAL float* overlap_out,
                              gr_float3* sum) {
  int count = 0;
  gr_uint k;
  gr_float3 pi = gr_load3(p, i);
  float ri = g->radius[i];
  float repulse = prm->internal_collisions_weight > 0.0f ? gr_repulsion_scale(g, prm, i) : 0.0f;
  float clump = prm->clumping_weight > 0.0f ? gr_clump_scale(g, prm, i) : 0.0f;
  /* squared reach of a candidate that can act, in units of (r_i + r_j)^2 */
  float reach2 = clump > 0.0f ? prm->neighbor_query_scale * prm->neighbor_query_scale : 1.0f;
  int skip_constrained = g->con_offsets && !prm->collide_mutually_constrained_particles && !g->nbr_unconstrained;
  if (!(clump > 0.0f) && !skip_constrained && prm->mass_shock != 2) {
    if (!(repulse > 0.0f)) {
      if (overlap_out)
        for (k = g->nbr_offsets[i]; k < g->nbr_offsets[i + 1]; ++k) overlap_out[k - g->nbr_offsets[i]] = 0.0f;
      return 0;
    }
    if (g->uniform_radius > 0.0f && g->uniform_inv_mass > 0.0f)
      return gr_gather_contacts_lanes(g, p, i, repulse, overlap_out, sum, 1);
    return gr_gather_contacts_lanes(g, p, i, repulse, overlap_out, sum, 0);
  }
  gr_float3 acc = gr_make3(0.0f, 0.0f, 0.0f);
  const gr_uint row_begin = g->nbr_offsets[i], row_end = g->nbr_offsets[i + 1];
  for (k = row_begin; k < row_end; ++k) {
    int j = (int)g->nbr_indices[k];
    gr_float3 xij = gr_sub(pi, gr_load3(p, j));
    float d2 = gr_dot(xij, xij);
    float rsum = ri + g->radius[j];
    if (overlap_out) overlap_out[k - row_begin] = 0.0f;
    if (!(d2 < reach2 * rsum * rsum) || j == i) continue;
    /* constrained pairs do not collide unless asked (help page "Collide Mutually Constrained
     * Particles"); they keep their rest length instead */
    if (skip_constrained && gr_constrained(g, i, j)) continue;
    float dist = gr_sqrt(d2);
    gr_float3 corr;
    if (dist < rsum) {
      if (!(repulse > 0.0f)) continue;
      gr_float3 n = gr_pair_normal(xij, dist, i, j);
      float d = rsum - dist;
      float share = gr_pair_share(g, prm, i, j);
      corr = gr_scale(n, share * d * repulse);
      if (overlap_out) overlap_out[k - row_begin] = d;
    } else if (clump > 0.0f && dist < prm->neighbor_query_scale * rsum) {
      gr_float3 n = gr_scale(xij, 1.0f / dist);
      corr = gr_clump_pair(n, dist - rsum, gr_plain_share(g, i, j), clump);
    } else {
      continue;
    }
    if (corr.x != 0.0f || corr.y != 0.0f || corr.z != 0.0f) {
      acc = gr_add(acc, corr);
      ++count;
    }
  }
  *sum = gr_add(*sum, acc);
  return count;
}

/* The sums gr_friction_pass combines a grain's contacts from (each contact c with tangential
 * slip s_c over the substep, |s_c| = sl_c > 0, that pushed its pair apart in the substep: a_c > 0,
 * the relative normal correction it applied, summed over the iterations). */
typedef struct {
  gr_float3 target;  /* sum of sl_c x (-share_c s_c): removals weighted by slip */
  gr_float3 plain;   /* sum of -share_c s_c (disable_constraint_averaging) */
  float weight;      /* sum of sl_c */
  float bound;       /* sum of sl_c x mu_c x share_c x a_c */
  float largest;     /* max sl_c */
} gr_slip_sums;

GR_INLINE void gr_add_slip(gr_slip_sums* f, gr_float3 s, float sl, float share, float mu, float a) {
  f->target = gr_madd(f->target, s, -sl * share);
  f->plain = gr_madd(f->plain, s, -share);
  f->weight += sl;
  f->bound += sl * mu * share * a;
  f->largest = gr_max(f->largest, sl);
}

/* Grain i's contacts with its neighbours into *f (see gr_slip_sums); normal[k] holds a_c as
 * float bits per neighbour entry. */
GR_INLINE void gr_gather_pair_slip(const gr_grains* g, const gr_params* prm,
                                   const GR_GLOBAL float* p, const GR_GLOBAL gr_uint* normal, int i,
                                   gr_slip_sums* f) {
  const gr_float3 pi = gr_load3(p, i);
  const gr_float3 di = gr_sub(pi, gr_load3(g->P, i));
  const float mu = prm->friction_with_particles * gr_attr(g->friction, i);
  gr_uint k;
  for (k = g->nbr_offsets[i]; k < g->nbr_offsets[i + 1]; ++k) {
    int j = (int)g->nbr_indices[k];
    float a = gr_as_float(normal[k]);
    if (j == i || !(a > 0.0f)) continue;
    gr_float3 pj = gr_load3(p, j);
    gr_float3 xij = gr_sub(pi, pj);
    gr_float3 n = gr_pair_normal(xij, gr_length(xij), i, j);
    gr_float3 dx = gr_sub(di, gr_sub(pj, gr_load3(g->P, j)));
    if (g->pair_slip) dx = gr_add(dx, gr_load3(g->pair_slip, (int)k));
    gr_float3 s = gr_madd(dx, n, -gr_dot(dx, n));
    float sl = gr_length(s);
    if (sl > 0.0f) gr_add_slip(f, s, sl, gr_pair_share(g, prm, i, j), mu, a);
  }
}

/* Contact history (GrainsSolver::save_history): a stuck contact remembers at most this much slip,
 * as a DEM contact's tangential spring saturates at mu F_n / k_t (a fraction of its normal
 * overlap): contact_memory x the static coefficient x the summed radii, and never more than one
 * substep of its static friction can pull back, the static coefficient x a, the normal
 * correction the contact applied in the substep (the bound gr_friction_pass used). A remembered
 * slip beyond that bound fails the next substep's static test before anything moves, so the
 * contact would stay kinetic in every later substep and a heap at rest would creep (the demo's
 * heap sank 12 mm in 2 s from rest with the first cap alone, 5 mm with both:
 * docs/heap-angle.md). Slip beyond the cap is sliding, forgotten. */
GR_INLINE float gr_pair_history_cap(const gr_grains* g, const gr_params* prm, int i, int j,
                                    float a) {
  const float mu = prm->friction_with_particles * prm->static_threshold * gr_attr(g->friction, i);
  return mu * gr_min(prm->contact_memory * (g->radius[i] + g->radius[j]), a);
}
GR_INLINE float gr_plane_history_cap(const gr_grains* g, const gr_params* prm, int i, float a) {
  const float mu = prm->friction_with_colliders * prm->static_threshold * gr_attr(g->friction, i);
  return mu * gr_min(prm->contact_memory * 2 * g->radius[i], a);
}

#endif /* GRAINS_KERNELS_CONTACT_H */
