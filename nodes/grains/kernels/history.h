/* The Jacobi path's contact history (GrainsSolver::save_history and load_history), grain by
 * grain: the host runs these functions through nodes/grains/history.cpp, a device through
 * opencl/grains.cl (gr_k_save_pair_slips, gr_k_load_pair_slips, gr_k_save_plane_slips,
 * gr_k_load_plane_slips), and both write the same floats: every product and sum is written out
 * without a multiply and an add fused (the device's FP_CONTRACT off here, the host's file compiled
 * with -ffp-contract=off) and without OpenCL's dot(), whose order a device chooses.
 *
 * Each entry of a grain's neighbour row, and of its row of collider planes, keeps a slip (3
 * floats): what the contact slid tangentially in the substep and did not give back, which the
 * next substep's friction removes with its own (kernels/contact.h, gr_pair_history_cap,
 * gr_plane_history_cap). */
#ifndef GRAINS_KERNELS_HISTORY_H
#define GRAINS_KERNELS_HISTORY_H
#include "contact.h"
#include "row_stats.h"

GR_INLINE float gr_history_dot(gr_float3 a, gr_float3 b) {
  GR_ROW_EXACT
  const float xx = a.x * b.x, yy = a.y * b.y, zz = a.z * b.z;
  return xx + yy + zz;
}

/* Grain i's slips saved at the end of the substep into out (3 floats an entry of its row in
 * g->nbr_offsets and g->nbr_indices): for an entry that pushed in the substep (pair_normal, the
 * bits of its accumulated normal correction, above 0), the tangential part of the pair's
 * relative move (p, where the iterations ended, less the start g->P, of each grain) plus the slip
 * it carried in (g->pair_slip), at most gr_pair_history_cap long; 0 for the others. */
GR_INLINE void gr_save_pair_slips(const gr_grains* g, const gr_params* prm,
                                  const GR_GLOBAL float* p, const GR_GLOBAL gr_uint* pair_normal,
                                  int i, GR_GLOBAL float* out) {
  GR_ROW_EXACT
  const gr_float3 pi = gr_load3(p, i);
  const gr_float3 di = gr_sub(pi, gr_load3(g->P, i));
  gr_uint k;
  for (k = g->nbr_offsets[i]; k < g->nbr_offsets[i + 1]; ++k) {
    const int j = (int)g->nbr_indices[k];
    const float a = gr_as_float(pair_normal[k]);
    gr_float3 h = gr_make3(0.0f, 0.0f, 0.0f);
    if (j != i && a > 0.0f) {
      const gr_float3 pj = gr_load3(p, j);
      const gr_float3 dx =
          gr_add(gr_sub(di, gr_sub(pj, gr_load3(g->P, j))), gr_load3(g->pair_slip, (int)k));
      const gr_float3 xij = gr_sub(pi, pj);
      const gr_float3 nn = gr_pair_normal(xij, gr_sqrt(gr_history_dot(xij, xij)), i, j);
      h = gr_sub(dx, gr_scale(nn, gr_history_dot(dx, nn)));
      const float cap = gr_pair_history_cap(g, prm, i, j, a);
      const float l = gr_sqrt(gr_history_dot(h, h));
      if (l > cap) h = gr_scale(h, cap / l);
    }
    gr_store3(out, (int)k, h);
  }
}

/* Grain i's collider-plane slips saved at the end of the substep into out (3 floats an entry of
 * its row of planes, g->plane_offsets and g->plane: a point, the normal and the collider's
 * velocity, 3 floats each): for an entry whose plane pushed in the substep (collider_normal, its
 * summed normal correction, above 0), the tangential part of the grain's move (p less the start
 * g->P) less the collider's own over dt, plus the slip it carried in (g->plane_slip), at most
 * gr_plane_history_cap long; 0 for the others. */
GR_INLINE void gr_save_plane_slips(const gr_grains* g, const gr_params* prm,
                                   const GR_GLOBAL float* p, const GR_GLOBAL float* collider_normal,
                                   int i, GR_GLOBAL float* out) {
  GR_ROW_EXACT
  const gr_float3 di = gr_sub(gr_load3(p, i), gr_load3(g->P, i));
  gr_uint e;
  for (e = g->plane_offsets[i]; e < g->plane_offsets[i + 1]; ++e) {
    const float a = collider_normal[e];
    gr_float3 h = gr_make3(0.0f, 0.0f, 0.0f);
    if (a > 0.0f) {
      const GR_GLOBAL float* pl = g->plane + 9 * (size_t)e;
      const gr_float3 nn = gr_make3(pl[3], pl[4], pl[5]);
      const gr_float3 dx = gr_add(gr_sub(di, gr_scale(gr_make3(pl[6], pl[7], pl[8]), prm->dt)),
                                  gr_load3(g->plane_slip, (int)e));
      h = gr_sub(dx, gr_scale(nn, gr_history_dot(dx, nn)));
      const float cap = gr_plane_history_cap(g, prm, i, a);
      const float l = gr_sqrt(gr_history_dot(h, h));
      if (l > cap) h = gr_scale(h, cap / l);
    }
    gr_store3(out, (int)e, h);
  }
}

/* Grain i's carried slips into slip (3 floats an entry of its row in offsets and indices): for
 * each entry, the slip the last substep saved for the same pair of grains, found by id in that
 * substep's row of the grain (h: its index there, below 0 for none; hist_offsets and
 * hist_indices that substep's rows, hist_id its grains' ids, hist_slip what it saved); 0 where
 * there is none. id and hist_id null: a grain's id is its index. */
GR_INLINE void gr_load_pair_slips(const GR_GLOBAL gr_uint* offsets,
                                  const GR_GLOBAL gr_uint* indices, const GR_GLOBAL int* id, int i,
                                  int h, const GR_GLOBAL gr_uint* hist_offsets,
                                  const GR_GLOBAL gr_uint* hist_indices,
                                  const GR_GLOBAL int* hist_id, const GR_GLOBAL float* hist_slip,
                                  GR_GLOBAL float* slip) {
  gr_uint k, m;
  for (k = offsets[i]; k < offsets[i + 1]; ++k) {
    const int j = (int)indices[k];
    const int other = id ? id[j] : j;
    gr_float3 s = gr_make3(0.0f, 0.0f, 0.0f);
    if (h >= 0)
      for (m = hist_offsets[h]; m < hist_offsets[h + 1]; ++m) {
        const int was = (int)hist_indices[m];
        if ((hist_id ? hist_id[was] : was) == other) {
          s = gr_load3(hist_slip, (int)m);
          break;
        }
      }
    gr_store3(slip, (int)k, s);
  }
}

/* Grain i's carried collider-plane slips into slip (3 floats an entry of its row of planes,
 * offsets and which, each entry's collider): for each entry, the slip the last substep saved for
 * the same collider in that substep's row of the grain (h: its index there, below 0 for none;
 * hist_offsets and hist_which that substep's rows and colliders, hist_slip what it saved), among
 * the entries that pushed there (hist_normal, their summed normal corrections, above 0; null:
 * every entry, a history kept of those alone); 0 where there is none. */
GR_INLINE void gr_load_plane_slips(const GR_GLOBAL gr_uint* offsets, const GR_GLOBAL int* which,
                                   int i, int h, const GR_GLOBAL gr_uint* hist_offsets,
                                   const GR_GLOBAL int* hist_which,
                                   const GR_GLOBAL float* hist_normal,
                                   const GR_GLOBAL float* hist_slip, GR_GLOBAL float* slip) {
  gr_uint e, m;
  for (e = offsets[i]; e < offsets[i + 1]; ++e) {
    gr_float3 s = gr_make3(0.0f, 0.0f, 0.0f);
    if (h >= 0)
      for (m = hist_offsets[h]; m < hist_offsets[h + 1]; ++m)
        if (hist_which[m] == which[e] && (!hist_normal || hist_normal[m] > 0.0f)) {
          s = gr_load3(hist_slip, (int)m);
          break;
        }
    gr_store3(slip, (int)e, s);
  }
}

/* A rebuild of the rows during the iterations (update_neighbors_during_iterations): grain i's
 * entries in its rebuilt row (offsets, indices) take what the iterations accumulated for the
 * same neighbour in its row before (old_offsets, old_indices): the bits of its summed normal
 * correction (old_sum into sum) and its carried slip (old_slip into slip, 3 floats an entry;
 * both null: none); 0 for a neighbour new to the row. Copies only: the same bits on any side. */
GR_INLINE void gr_carry_pair_row(const GR_GLOBAL gr_uint* old_offsets,
                                 const GR_GLOBAL gr_uint* old_indices,
                                 const GR_GLOBAL gr_uint* old_sum, const GR_GLOBAL float* old_slip,
                                 const GR_GLOBAL gr_uint* offsets, const GR_GLOBAL gr_uint* indices,
                                 GR_GLOBAL gr_uint* sum, GR_GLOBAL float* slip, int i) {
  gr_uint k, m;
  for (k = offsets[i]; k < offsets[i + 1]; ++k) {
    gr_uint a = 0u;
    gr_float3 s = gr_make3(0.0f, 0.0f, 0.0f);
    for (m = old_offsets[i]; m < old_offsets[i + 1]; ++m)
      if (old_indices[m] == indices[k]) {
        a = old_sum[m];
        if (old_slip) s = gr_load3(old_slip, (int)m);
        break;
      }
    sum[k] = a;
    if (slip) gr_store3(slip, (int)k, s);
  }
}

/* A rebuild of the collider planes during the iterations (update_collisions_during_iterations):
 * grain i's entries in its rebuilt row of planes (offsets, which: each entry's collider) take
 * what the iterations accumulated for the same collider in its row before (old_offsets,
 * old_which), not for the same place in the nearest-first row: the summed normal correction
 * (old_sum into sum) and the carried slip (old_slip into slip, 3 floats an entry), each null
 * where there is none, and, in place, the impact data's applied corrections (slots: 3 floats a
 * slot, GR_MAX_PLANES slots a grain, the k-th slot its row's k-th entry; null: none); a collider
 * the rebuilt row no longer holds takes its own with it. Copies only. */
GR_INLINE void gr_carry_plane_row(const GR_GLOBAL gr_uint* old_offsets,
                                  const GR_GLOBAL int* old_which, const GR_GLOBAL float* old_sum,
                                  const GR_GLOBAL float* old_slip, const GR_GLOBAL gr_uint* offsets,
                                  const GR_GLOBAL int* which, GR_GLOBAL float* sum,
                                  GR_GLOBAL float* slip, GR_GLOBAL float* slots, int i) {
  float dx[3 * GR_MAX_PLANES];
  GR_GLOBAL float* mine = slots ? slots + 3 * GR_MAX_PLANES * (size_t)i : 0;
  const gr_uint b = offsets[i], pb = old_offsets[i];
  gr_uint e, m;
  int k;
  if (mine)
    for (k = 0; k < 3 * GR_MAX_PLANES; ++k) dx[k] = mine[k], mine[k] = 0.0f;
  for (e = b; e < offsets[i + 1]; ++e) {
    float a = 0.0f;
    gr_float3 s = gr_make3(0.0f, 0.0f, 0.0f);
    for (m = pb; m < old_offsets[i + 1]; ++m)
      if (old_which[m] == which[e]) {
        if (old_sum) a = old_sum[m];
        if (old_slip) s = gr_load3(old_slip, (int)m);
        if (mine)
          for (k = 0; k < 3; ++k) mine[3 * (e - b) + k] = dx[3 * (m - pb) + k];
        break;
      }
    if (sum) sum[e] = a;
    if (slip) gr_store3(slip, (int)e, s);
  }
}

#endif /* GRAINS_KERNELS_HISTORY_H */
