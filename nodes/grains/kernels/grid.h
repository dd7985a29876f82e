/* The neighbour rows of the OpenCL backend (opencl/neighbours.cpp launches it), a grain a
 * work-item: the same rows as the CPU path's search (engine/neighbors.cpp), which a pair's test
 * and a row's order define (engine/pair_test.h, shared), found with a simpler grid.
 *
 * One level of cells as wide as the largest pair distance, h > qs (2 r_max), over the bounding
 * box of the finite positions: a pair that passes the test lies in cells at most one apart along
 * each axis, so a grain reads the 27 cells around its own. (h carries a relative margin of 1e-5
 * over the float t the test rounds to; a cell coordinate is computed in double, whose rounding at
 * 2^31 cells is 5e-7 of a cell.) An axis of at most `ext` cells is stored densely (dim = ext) or,
 * when the box holds many more cells than grains, wrapped on a power of two of at least 4 cells:
 * a far cell then shares a slot, which only adds candidates the test rejects, and the three
 * cells a window spans along the axis stay distinct. Coordinates are clamped to [0, ext - 1];
 * NaN goes to 0. A grain with a position that is not finite has an empty row (no distance to it
 * passes the test).
 *
 * The cells hold their grains in any order (the placing counts up atomically): a row is sorted
 * by its unique keys, so it does not depend on that order. A row keeps the max_neighbors
 * nearest (all when max_neighbors <= 0), as the CPU's does.
 *
 * Needs double precision (cl_khr_fp64): the pair test is in double. */
#ifndef GRAINS_KERNELS_GRID_H
#define GRAINS_KERNELS_GRID_H

#include "prelude.h"
/* the device's program holds engine/pair_test.h beside the kernel headers (embed_kernels.cmake) */
#if defined(GR_OPENCL)
#include "pair_test.h"
#else
#include "engine/pair_test.h"
#endif

#if defined(GR_OPENCL)
typedef long gr_long;
#else
typedef int64_t gr_long;
#endif

/* the grid of one search (host-made, a kernel argument: 8-byte fields first, the same layout on
 * both sides) */
typedef struct {
  double lo[3];      /* origin: the finite positions' smallest coordinates, m */
  double inv_h;      /* 1 / cell width, 1/m */
  gr_long ext[3];    /* cells the box spans along each axis */
  gr_long dim[3];    /* cells stored along each axis: ext, or a power of two >= 4 below it */
  float qs;          /* neighbor_query_scale */
  int max_neighbors; /* the most a row keeps; <= 0: all */
} gr_grid;

/* a grid coordinate u (cells from lo) as a cell index along an axis of ext cells */
GR_INLINE gr_long gr_grid_coord(double u, gr_long ext) {
  if (!(u >= 0.0)) return 0;
  if (u >= (double)ext) return ext - 1;
  return (gr_long)u;
}

/* grain i's cell along each axis */
GR_INLINE void gr_grid_cell(const gr_grid* g, GR_GLOBAL const float* P, int i, gr_long* c) {
  int a;
  for (a = 0; a < 3; ++a)
    c[a] = gr_grid_coord(((double)P[3 * i + a] - g->lo[a]) * g->inv_h, g->ext[a]);
}

/* the slot of cell (cx, cy, cz) */
GR_INLINE gr_uint gr_grid_key(const gr_grid* g, gr_long cx, gr_long cy, gr_long cz) {
  const gr_long wx = cx < g->dim[0] ? cx : (cx & (g->dim[0] - 1));
  const gr_long wy = cy < g->dim[1] ? cy : (cy & (g->dim[1] - 1));
  const gr_long wz = cz < g->dim[2] ? cz : (cz & (g->dim[2] - 1));
  return (gr_uint)((wz * g->dim[1] + wy) * g->dim[0] + wx);
}

GR_INLINE gr_uint gr_grid_key_of(const gr_grid* g, GR_GLOBAL const float* P, int i) {
  gr_long c[3];
  gr_grid_cell(g, P, i, c);
  return gr_grid_key(g, c[0], c[1], c[2]);
}

/* grain i's cell along each axis, or 0 (with c unset) when its position is not finite (its row
 * is then empty) */
GR_INLINE int gr_grid_centre(const gr_grid* g, GR_GLOBAL const float* P, int i, gr_long* c) {
  if (!(isfinite(P[3 * i]) && isfinite(P[3 * i + 1]) && isfinite(P[3 * i + 2]))) return 0;
  gr_grid_cell(g, P, i, c);
  return 1;
}

/* the slots of the cells around cell c in the k-th (0..8) row of x cells (dy, dz = -1, 0, 1):
 * [run[0], run[1]) and [run[2], run[3]) (the second empty unless the row's window wraps round
 * the stored cells); a row outside the box has none. A row's cells are consecutive keys, so
 * their slots are one run: the 27 cells of a window are 9 runs (the cells are distinct: a
 * wrapped axis stores at least 4). */
GR_INLINE void gr_grid_run(const gr_grid* g, GR_GLOBAL const gr_uint* start, const gr_long* c,
                           int k, gr_uint* run) {
  const gr_long y = c[1] + k % 3 - 1, z = c[2] + k / 3 - 1;
  gr_long x0, x1, w0, w1, base;
  run[0] = run[1] = run[2] = run[3] = 0;
  if (y < 0 || y >= g->ext[1] || z < 0 || z >= g->ext[2]) return;
  x0 = c[0] > 0 ? c[0] - 1 : 0;
  x1 = c[0] + 1 < g->ext[0] ? c[0] + 1 : g->ext[0] - 1;
  base = (gr_long)gr_grid_key(g, 0, y, z);
  w0 = x0 < g->dim[0] ? x0 : (x0 & (g->dim[0] - 1));
  w1 = x1 < g->dim[0] ? x1 : (x1 & (g->dim[0] - 1));
  if (w0 <= w1) {
    run[0] = start[base + w0];
    run[1] = start[base + w1 + 1];
  } else { /* x0 .. x1 passes the end of the stored row */
    run[0] = start[base + w0];
    run[1] = start[base + g->dim[0]];
    run[2] = start[base];
    run[3] = start[base + w1 + 1];
  }
}

/* a float pre-test that passes every pair gr_pair_ok passes (d2 in float is within a few
 * roundings of the double sum, t^2 within one; widened by 1e-4) and rejects most candidates
 * with no double arithmetic; thresholds near float underflow go straight to the double test */
GR_INLINE int gr_grid_near(float px, float py, float pz, GR_GLOBAL const float* q, float t) {
  const float dx = px - q[0], dy = py - q[1], dz = pz - q[2];
  return !(t > 1e-18f) || dx * dx + dy * dy + dz * dz <= t * t * 1.0001f;
}

/* the length of grain i's row: its neighbours among the grains of the cells around it (cell c
 * holds the slots [start[c], start[c + 1]): slot s is grain grains[s], whose position and radius
 * are copied to sorted[4 s ...], so that a cell's candidates are read in one run), at most
 * max_neighbors */
GR_INLINE gr_uint gr_grid_row_count(const gr_grid* g, GR_GLOBAL const float* P,
                                    GR_GLOBAL const float* radius, GR_GLOBAL const gr_uint* start,
                                    GR_GLOBAL const gr_uint* grains, GR_GLOBAL const float* sorted,
                                    int i) {
  gr_uint count = 0, s;
  gr_long c[3];
  const float px = P[3 * i], py = P[3 * i + 1], pz = P[3 * i + 2], r = radius[i];
  gr_uint run[4];
  int k, h;
  if (!gr_grid_centre(g, P, i, c)) return 0;
  for (k = 0; k < 9; ++k) {
    gr_grid_run(g, start, c, k, run);
    for (h = 0; h < 4; h += 2)
      for (s = run[h]; s < run[h + 1]; ++s) {
        GR_GLOBAL const float* q = sorted + 4 * (size_t)s;
        count += (grains[s] != (gr_uint)i) &
                 gr_pair_ok(gr_pair_dist2(px, py, pz, q[0], q[1], q[2]), g->qs, r, q[3]);
      }
  }
  return g->max_neighbors > 0 && count > (gr_uint)g->max_neighbors ? (gr_uint)g->max_neighbors
                                                                   : count;
}

/* grain i's row into indices[begin, end) (end - begin: gr_grid_row_count's length), nearest
 * first: the candidates stream through keys[begin, end), which keeps the smallest keys seen so
 * far in order (an insertion that drops the largest once the row is full) */
GR_INLINE void gr_grid_row_fill(const gr_grid* g, GR_GLOBAL const float* P,
                                GR_GLOBAL const float* radius, GR_GLOBAL const gr_uint* start,
                                GR_GLOBAL const gr_uint* grains, GR_GLOBAL const float* sorted,
                                int i, gr_uint begin, gr_uint end, GR_GLOBAL gr_pair_key_t* keys,
                                GR_GLOBAL gr_uint* indices) {
  gr_uint s, len = 0;
  gr_long c[3];
  const gr_uint cap = end - begin;
  const float px = P[3 * i], py = P[3 * i + 1], pz = P[3 * i + 2], r = radius[i];
  gr_uint run[4];
  int k, h;
  if (cap == 0 || !gr_grid_centre(g, P, i, c)) return;
  for (k = 0; k < 9; ++k) {
    gr_grid_run(g, start, c, k, run);
    for (h = 0; h < 4; h += 2)
      for (s = run[h]; s < run[h + 1]; ++s) {
        GR_GLOBAL const float* q = sorted + 4 * (size_t)s;
        gr_uint j, at;
        double d2;
        gr_pair_key_t key;
        if (!gr_grid_near(px, py, pz, q, g->qs * (r + q[3]))) continue;
        d2 = gr_pair_dist2(px, py, pz, q[0], q[1], q[2]);
        j = grains[s];
        if (j == (gr_uint)i || !gr_pair_ok(d2, g->qs, r, q[3])) continue;
        key = gr_pair_key(d2, j);
        if (len == cap && key >= keys[begin + cap - 1]) continue;
        at = len < cap ? len++ : cap - 1; /* full: the largest key makes way */
        while (at > 0 && keys[begin + at - 1] > key) {
          keys[begin + at] = keys[begin + at - 1];
          --at;
        }
        keys[begin + at] = key;
      }
  }
  for (s = 0; s < len; ++s) indices[begin + s] = (gr_uint)(keys[begin + s] & 0xffffffffu);
}

#endif
