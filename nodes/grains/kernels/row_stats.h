/* What the host reads along the neighbour rows after a substep, for a run of grains: the
 * overlap statistics error control measures (GrainsSolver::contact_stats) and the reach of the
 * rows cut at max_neighbors (the Verlet skin, GrainsSolver::remember_rows). The CPU takes all
 * grains as one run; a device takes runs in parallel and the host combines them in run order
 * (opencl/neighbours.cpp), so that neither the rows nor a serial pass over them crosses to the host.
 *
 * Overlap of a touching pair (i < j, each pair once, from i's row): (r_i + r_j - |x_ij|) /
 * (r_i + r_j). Reach of a full row: its farthest candidate's distance beyond r_i + r_max. Needs
 * double precision (the overlaps' sum): on a device, with cl_khr_fp64, as the rows themselves. */
#ifndef GRAINS_KERNELS_ROW_STATS_H
#define GRAINS_KERNELS_ROW_STATS_H
#include "prelude.h"

/* the grains [first, end): touching pairs (added to *contacts), the largest overlap (into
 * *largest) and the overlaps' sum (added to *sum, in row order) */
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

#endif /* GRAINS_KERNELS_ROW_STATS_H */
