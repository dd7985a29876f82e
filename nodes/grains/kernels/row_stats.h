/* What the host reads along the neighbour rows after a substep, for a run of grains: the
 * overlap statistics error control measures (GrainsSolver::contact_stats), the reach of the
 * rows cut at max_neighbors (the Verlet skin, GrainsSolver::remember_rows) and how far the
 * grains have moved since the rows were built (the Verlet test, GrainsSolver::keep_rows). The
 * CPU takes all grains as one run; a device takes runs in parallel and the host combines them
 * in run order (opencl/neighbours.cpp), so that neither the rows nor a serial pass over them
 * crosses to the host.
 *
 * Overlap of a touching pair (i < j, each pair once, from i's row): (r_i + r_j - |x_ij|) /
 * (r_i + r_j). Reach of a full row: its farthest candidate's distance beyond r_i + r_max. Needs
 * double precision (the overlaps' sum): on a device, with cl_khr_fp64, as the rows themselves. */
#ifndef GRAINS_KERNELS_ROW_STATS_H
#define GRAINS_KERNELS_ROW_STATS_H
#include "prelude.h"

/* the grains [first, end): touching pairs (added to *contacts), the largest overlap (into
 * *largest) and the overlaps' sum (added to *sum, in row order); on a device with double
 * precision only (a program without it has none of the rows' kernels) */
#if !defined(GR_OPENCL) || defined(GR_DOUBLES)
GR_INLINE void gr_row_overlaps(const GR_GLOBAL float* P, const GR_GLOBAL float* radius,
                               const GR_GLOBAL gr_uint* offsets, const GR_GLOBAL gr_uint* indices,
                               int first, int end, double* contacts, float* largest, double* sum) {
  int i;
  gr_uint k;
  for (i = first; i < end; ++i) {
    const gr_float3 pi = gr_load3(P, i);
    for (k = offsets[i]; k < offsets[i + 1]; ++k) {
      const int j = (int)indices[k];
      float rsum, overlap, pen;
      gr_float3 dij;
      if (j <= i) continue;
      rsum = radius[i] + radius[j];
      dij = gr_sub(pi, gr_load3(P, j));
      if (!(gr_dot(dij, dij) < rsum * rsum)) continue; /* apart, without a square root */
      overlap = rsum - gr_length(dij);
      if (overlap <= 0.0f) continue;
      pen = overlap / rsum;
      *largest = gr_max(*largest, pen);
      *sum += (double)pen;
      *contacts += 1.0;
    }
  }
}
#endif

/* the smallest reach of the grains [first, end) whose rows hold `full` candidates or more (full
 * 0: none is cut), into *reach; r_max: the largest radius */
GR_INLINE void gr_row_reach(const GR_GLOBAL float* p, const GR_GLOBAL float* radius,
                            const GR_GLOBAL gr_uint* offsets, const GR_GLOBAL gr_uint* indices,
                            int first, int end, gr_uint full, float r_max, float* reach) {
  int i;
  gr_uint k;
  for (i = first; i < end; ++i) {
    float far2 = 0.0f;
    if (full == 0u || offsets[i + 1] - offsets[i] < full) continue;
    for (k = offsets[i]; k < offsets[i + 1]; ++k) {
      const gr_float3 d = gr_sub(gr_load3(p, i), gr_load3(p, (int)indices[k]));
      far2 = gr_max(far2, gr_dot(d, d));
    }
    *reach = gr_min(*reach, gr_sqrt(far2) - (radius[i] + r_max));
  }
}

/* the most entries a row of the grains [first, end) holds, into *longest (the Jacobi contact
 * loop's row scratch is that long) */
GR_INLINE void gr_row_longest(const GR_GLOBAL gr_uint* offsets, int first, int end,
                              gr_uint* longest) {
  int i;
  for (i = first; i < end; ++i) {
    const gr_uint count = offsets[i + 1] - offsets[i];
    if (count > *longest) *longest = count;
  }
}

/* The grains node's sleeping test (nodes/grains/grains_node.cpp, update_sleep) reads grain k's
 * row at the written world positions P: how many neighbours lie within 1.05 and within 1.25
 * times the summed radii (a sleeper wakes when its contacts of 1.05 are no longer within 1.25),
 * and whether a `fast` one (an awake grain moving faster than it wakes a neighbour) lies within
 * 1.05. The host and a device must count alike, bit for bit: the distance is written out
 * without a multiply and an add fused (the device's FP_CONTRACT off here; the host's
 * nodes/grains/sleep_rows.cpp is compiled with -ffp-contract=off) and OpenCL's dot(), whose
 * order a device chooses, is not used. */
#ifdef GR_OPENCL
#define GR_ROW_EXACT _Pragma("OPENCL FP_CONTRACT OFF")
#else
#define GR_ROW_EXACT
#endif

/* |P_j - P_k| within reach x (r_k + r_j) */
GR_INLINE int gr_row_within(const GR_GLOBAL float* P, const GR_GLOBAL float* radius, int k, int j,
                            float reach) {
  GR_ROW_EXACT
  const float x = P[3 * j] - P[3 * k], y = P[3 * j + 1] - P[3 * k + 1],
              z = P[3 * j + 2] - P[3 * k + 2];
  return gr_sqrt(x * x + y * y + z * z) < reach * (radius[k] + radius[j]);
}

/* The Verlet test of the rows kept across substeps (GrainsSolver::keep_rows): the largest
 * squared distance any grain of [first, end) has moved from b, the predicted positions the rows
 * were built from, to p, this substep's, into *moved2. Written out unfused, so that the host
 * and a device keep or rebuild the rows in the same substeps. */
GR_INLINE void gr_rows_moved(const GR_GLOBAL float* p, const GR_GLOBAL float* b, int first,
                             int end, float* moved2) {
  GR_ROW_EXACT
  int i;
  for (i = first; i < end; ++i) {
    const float x = p[3 * i] - b[3 * i], y = p[3 * i + 1] - b[3 * i + 1],
                z = p[3 * i + 2] - b[3 * i + 2];
    *moved2 = gr_max(*moved2, x * x + y * y + z * z);
  }
}

/* grain k's neighbours within reach x (r_k + r_j) */
GR_INLINE gr_uint gr_row_near(const GR_GLOBAL float* P, const GR_GLOBAL float* radius,
                              const GR_GLOBAL gr_uint* offsets, const GR_GLOBAL gr_uint* indices,
                              int k, float reach) {
  gr_uint e, count = 0u;
  for (e = offsets[k]; e < offsets[k + 1]; ++e)
    count += (gr_uint)gr_row_within(P, radius, k, (int)indices[e], reach);
  return count;
}

/* whether one of grain k's neighbours flagged in `fast` lies within reach x (r_k + r_j) */
GR_INLINE int gr_row_fast_near(const GR_GLOBAL float* P, const GR_GLOBAL float* radius,
                               const GR_GLOBAL gr_uint* offsets, const GR_GLOBAL gr_uint* indices,
                               const GR_GLOBAL unsigned char* fast, int k, float reach) {
  gr_uint e;
  for (e = offsets[k]; e < offsets[k + 1]; ++e) {
    const int j = (int)indices[e];
    if (fast[j] && gr_row_within(P, radius, k, j, reach)) return 1;
  }
  return 0;
}

/* grain k's sleeping reads in one word: bits 0-14 its neighbours within 1.05, bits 15-29 within
 * 1.25, bit 30 a fast one within 1.05, bit 31 a count past GR_SLEEP_COUNT_MAX (the host then
 * counts along the rows itself) */
#define GR_SLEEP_NEAR 1.05f
#define GR_SLEEP_KEPT 1.25f
#define GR_SLEEP_COUNT_MAX 32767u
#define GR_SLEEP_FAST (1u << 30)
#define GR_SLEEP_OVER (1u << 31)
GR_INLINE gr_uint gr_row_sleep(const GR_GLOBAL float* P, const GR_GLOBAL float* radius,
                               const GR_GLOBAL gr_uint* offsets, const GR_GLOBAL gr_uint* indices,
                               const GR_GLOBAL unsigned char* fast, int k) {
  const gr_uint near = gr_row_near(P, radius, offsets, indices, k, GR_SLEEP_NEAR);
  const gr_uint kept = gr_row_near(P, radius, offsets, indices, k, GR_SLEEP_KEPT);
  const int woken = gr_row_fast_near(P, radius, offsets, indices, fast, k, GR_SLEEP_NEAR);
  if (near > GR_SLEEP_COUNT_MAX || kept > GR_SLEEP_COUNT_MAX) return GR_SLEEP_OVER;
  return near | (kept << 15) | (woken ? GR_SLEEP_FAST : 0u);
}

#endif /* GRAINS_KERNELS_ROW_STATS_H */
