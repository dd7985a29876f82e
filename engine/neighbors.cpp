// Neighbour search over spheres: a uniform grid (one level) or a multi-level grid (one level per
// power of two of radius), binned with a counting sort and queried per run of particles sharing a
// cell; brute force as the reference.
//
// Exactness. The grid and brute force decide a pair with the same helpers: pair_dist2 (float
// differences, squared and summed in double: every product is exact, so the result does not
// depend on whether the compiler fuses multiply-adds) and pair_ok (t = qs * (ri + rj) in float,
// d2 < t^2 in double; no pair when t <= 0 or NaN); pair_key orders a list by distance (at float
// precision), then original index. The grid has to guarantee that every pair passing pair_ok lies
// in a gathered cell: cell coordinates are a monotone function of the position (double arithmetic,
// clamped), and every window is widened by a relative and an absolute 1e-5 cell, far above the
// float rounding of the test. A float pre-test (widened by 1e-4, so it passes everything pair_ok
// passes) picks the few candidates pair_ok then decides.
//
// Grid. Levels cover the bounding box of all points, with cells as wide as the level's largest
// interaction distance, qs * 2 * (largest radius in the level). When the box has few enough cells
// a level is dense; otherwise it wraps around with power-of-two periods per axis (a spatial hash
// without collisions inside any window: far cells may share a bucket, which only adds candidates
// that the distance test rejects; a far outlier costs nothing). Keys of one row of x cells stay
// contiguous either way, so a window is one or two slot ranges per row.
//
// Mixed radii. A particle queries its own level and the larger ones, with the reach
// qs * (its level's largest radius + the other level's); a pair across levels is found from the
// smaller particle's side only and handed to the larger one, so large grains never walk the many
// small cells of small levels. Lists then merge what a particle found and what was handed to it.
//
// Determinism. A list depends only on the input: queries run over chunks of sorted slots (dynamic
// schedule, for balance), each chunk noting where its lists went; handed-over pairs are grouped by
// a counting sort whose order inside a group does not matter (every list is sorted by unique keys
// at the end); a final pass writes every list at its place in original-index order.
//
// Buffers. keys_ (or the caller's store): cell keys for the counting sort, then the store the
// query pass's chunks put their lists in. order_: sorted slot -> original index. scratch_:
// sorted x, y, z, r arrays. cell_start_: cell starts, per-chunk list positions, per-slot
// counts, handed-over group starts and groups.
// Per-thread scratch lives in a thread_local struct (the header has no per-thread member). All
// keep their capacity, so nothing is allocated once sizes settle.
#include "engine/neighbors.h"

#include <omp.h>
#if defined(__AVX512F__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include "engine/buffer.h"
#include "engine/pair_test.h"

namespace grains {
namespace {

constexpr int kMaxThreads = 256;
constexpr int kBins = 257;                      // float exponents 0..255, plus radius <= 0 / NaN
constexpr int64_t kCellMax = (int64_t(1) << 31) - 2;  // largest cell coordinate along an axis
constexpr double kRelSlack = 1e-5, kAbsSlack = 1e-5;
// Float pre-test margin: d2 in float is within 3 roundings of the exact sum, t * t within one.
constexpr float kPreWiden = 1.0001f;
constexpr double kOriginShift = 0.381966011250105;  // 2 - golden ratio, in cells

// The pair test, its distance and the row order: engine/pair_test.h, shared with the OpenCL
// search (a row found there is this row).
inline double pair_dist2(float ax, float ay, float az, float bx, float by, float bz) {
  return gr_pair_dist2(ax, ay, az, bx, by, bz);
}
inline bool pair_ok(double d2, float qs, float ri, float rj) { return gr_pair_ok(d2, qs, ri, rj) != 0; }
inline uint64_t pair_key(double d2, uint32_t j) { return gr_pair_key(d2, j); }

// Keep at most K (K <= 0: all) smallest keys, sorted. Returns how many are kept.
// Lists of up to kRankMax keys are ranked instead: a key's place is the number of smaller keys,
// counted over all pairs in a branch-free loop that the compiler vectorises. Keys are unique (the
// index is part of them), so the places are a permutation and the result is the sorted order a
// comparison sort gives. At these sizes the m^2 compares cost less than the unpredictable
// branches of nth_element and insertion sort: a crushed 100k pile's lists hold 64 to 112
// candidates before the cut to max_neighbors, and ranking took its 8 substeps from 3.91-3.94 s
// to 3.46-3.78 s of CPU.
// Before ranking, a list longer than K is cut at the smallest of the distances dmax * q / 32
// (q = 1..32, found by bisection over vectorised counts) that has at least K keys at or below
// it: every key cut is farther than every key kept, so the cut is exact, and only the keys up
// to about the K-th nearest are ranked. On the settled 100k pile the ranking had taken 8.6% of
// the CPU (perf); cut first, ranking and cut take 2.2% and 4%, and 4 frames on one thread went
// from 3.25-3.41 s to 3.06-3.22 s.
// Lists of up to kCutMax keys are cut so: the cut also brings most lists longer than kRankMax
// down to ranking size, where they had gone to nth_element and sort (a crushed 100k pile's lists
// reach past 128 candidates, and the sort's insertion loops had taken a third of this function).
constexpr uint32_t kRankMax = 128;
constexpr uint32_t kCutMax = 1024;
inline uint32_t finish_candidates(uint64_t* c, uint32_t m, int K) {
  const uint32_t keep = K > 0 ? std::min(m, uint32_t(K)) : m;
  if (keep < m && m <= kCutMax) {
    float d[kCutMax];
    float dmax = 0;
    for (uint32_t a = 0; a < m; ++a) {
      d[a] = std::bit_cast<float>(uint32_t(c[a] >> 32));
      dmax = std::max(dmax, d[a]);
    }
    if (dmax > 0 && std::isfinite(dmax)) {
      auto at_most = [&](float t) {
        uint32_t count = 0;
        for (uint32_t a = 0; a < m; ++a) count += d[a] <= t;
        return count;
      };
      uint32_t lo = 0, hi = 32;  // at_most(dmax * hi / 32) = m >= keep
      while (hi - lo > 1) {
        const uint32_t mid = (lo + hi) / 2;
        if (at_most(dmax * (float(mid) / 32)) >= keep)
          hi = mid;
        else
          lo = mid;
      }
      const float cut = hi == 32 ? dmax : dmax * (float(hi) / 32);
      uint32_t kept = 0;
      for (uint32_t a = 0; a < m; ++a) {  // branch-free: which keys stay is unpredictable
        c[kept] = c[a];
        kept += d[a] <= cut;
      }
      m = kept;
    }
  }
  if (m <= kRankMax) {
    uint64_t v[kRankMax], rank[kRankMax];
    for (uint32_t a = 0; a < m; ++a) v[a] = c[a], rank[a] = 0;
    for (uint32_t b = 0; b < m; ++b) {
      const uint64_t vb = v[b];
      for (uint32_t a = 0; a < m; ++a) rank[a] += vb < v[a];
    }
    for (uint32_t a = 0; a < m; ++a)
      if (rank[a] < keep) c[rank[a]] = v[a];
    return keep;
  }
  if (keep < m) std::nth_element(c, c + keep, c + m);
  std::sort(c, c + keep);
  return keep;
}

// Cell coordinate of a (double) grid-space value: floor, clamped to [0, ext - 1]; NaN -> 0.
inline int64_t cell_coord(double u, int64_t ext) {
  if (!(u >= 0.0)) return 0;
  if (u >= double(ext)) return ext - 1;
  return int64_t(u);
}

// Distance (in cell units) from the interval [lo, hi] to cell c's interval [c, c + 1].
inline double gap(double lo, double hi, int64_t c) {
  const double a = double(c), b = a + 1.0;
  return hi < a ? a - hi : (lo > b ? lo - b : 0.0);
}

// Residue of a cell coordinate on an axis of `dim` stored cells: dim is either the full extent
// (c < dim always) or a power of two.
inline int64_t wrap(int64_t c, int64_t dim) { return c < dim ? c : (c & (dim - 1)); }

struct Grid {
  double lo[3] = {0, 0, 0};  // origin (bounding box minimum)
  double inv_h = 0;          // 1 / cell size
  int64_t ext[3] = {1, 1, 1};  // cells spanned per axis
  int64_t dim[3] = {1, 1, 1};  // cells stored per axis (ext: dense; a power of two: wrapped)
  uint32_t key_base = 0;     // first key of the level
  uint32_t begin = 0, end = 0;  // its sorted slots
  double rmax = 0;           // largest radius in the level
  uint32_t count = 0;

  uint32_t key(int64_t cx, int64_t cy, int64_t cz) const {
    return key_base +
           uint32_t((wrap(cz, dim[2]) * dim[1] + wrap(cy, dim[1])) * dim[0] + wrap(cx, dim[0]));
  }
  uint32_t key_of(const float* p) const {
    return key(cell_coord((double(p[0]) - lo[0]) * inv_h, ext[0]),
               cell_coord((double(p[1]) - lo[1]) * inv_h, ext[1]),
               cell_coord((double(p[2]) - lo[2]) * inv_h, ext[2]));
  }
  uint32_t cells() const { return uint32_t(dim[0] * dim[1] * dim[2]); }
};

// Chooses dense or wrapped storage for a level of `count` particles spanning ext cells: at most
// about 8 cells per particle, wrapped periods of 4 to 8 cells per particle.
void choose_dims(Grid& g, size_t count) {
  const double dense = double(g.ext[0]) * double(g.ext[1]) * double(g.ext[2]);
  if (dense <= 8.0 * double(count) + 64.0) {
    for (int a = 0; a < 3; ++a) g.dim[a] = g.ext[a];
    return;
  }
  int64_t target = 64;
  while (target < int64_t(4 * count)) target *= 2;
  g.dim[0] = g.dim[1] = g.dim[2] = 1;
  while (g.dim[0] * g.dim[1] * g.dim[2] < target) {
    int best = -1;
    double ratio = 1.0;
    for (int a = 0; a < 3; ++a) {
      double r = double(g.ext[a]) / double(g.dim[a]);
      if (g.dim[a] < g.ext[a] && r > ratio) best = a, ratio = r;
    }
    if (best < 0) break;
    g.dim[best] = std::min(g.dim[best] * 2, g.ext[best]);
  }
}

struct Stats {
  float lo[3], hi[3];   // bounding box over finite coordinates
  float rmin, rmax;     // over non-NaN radii
  size_t nan_radii;
  float rpos_min;       // smallest positive radius
  uint32_t bin_count[kBins];
  float bin_max[kBins];
};

inline int radius_bin(float r) {
  if (!(r > 0.0f) || !std::isfinite(r)) return kBins - 1;
  return int((std::bit_cast<uint32_t>(r) >> 23) & 0xffu);
}

void gather_stats(const float* P, const float* radius, size_t n, int T, bool bins, Stats& st) {
  const float inf = std::numeric_limits<float>::infinity();
  for (int a = 0; a < 3; ++a) st.lo[a] = inf, st.hi[a] = -inf;
  st.rmin = inf;
  st.rmax = -inf;
  st.nan_radii = 0;
  st.rpos_min = inf;
  std::fill(st.bin_count, st.bin_count + kBins, 0u);
  std::fill(st.bin_max, st.bin_max + kBins, 0.0f);
#pragma omp parallel num_threads(T)
  {
    float lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf}, rmin = inf, rmax = -inf;
    size_t nans = 0;
    float rpos = inf;
    uint32_t count[kBins] = {};
    float mx[kBins] = {};
#pragma omp for schedule(static) nowait
    for (ptrdiff_t i = 0; i < ptrdiff_t(n); ++i) {
      for (int a = 0; a < 3; ++a) {
        const float v = P[3 * i + a];
        if (std::isfinite(v)) {
          if (v < lo[a]) lo[a] = v;
          if (v > hi[a]) hi[a] = v;
        }
      }
      const float r = radius[i];
      if (r < rmin) rmin = r;
      if (r > rmax) rmax = r;
      nans += r != r;
      if (r > 0.0f && r < rpos) rpos = r;
      if (bins) {
        const int b = radius_bin(r);
        ++count[b];
        if (r > mx[b]) mx[b] = r;
      }
    }
    // min, max and sums do not depend on the order the threads merge in
#pragma omp critical(grains_neighbors_stats)
    {
      for (int a = 0; a < 3; ++a) {
        if (lo[a] < st.lo[a]) st.lo[a] = lo[a];
        if (hi[a] > st.hi[a]) st.hi[a] = hi[a];
      }
      if (rmin < st.rmin) st.rmin = rmin;
      if (rmax > st.rmax) st.rmax = rmax;
      st.nan_radii += nans;
      if (rpos < st.rpos_min) st.rpos_min = rpos;
      if (bins)
        for (int b = 0; b < kBins; ++b) {
          st.bin_count[b] += count[b];
          if (mx[b] > st.bin_max[b]) st.bin_max[b] = mx[b];
        }
    }
  }
  for (int a = 0; a < 3; ++a)
    if (!(st.lo[a] <= st.hi[a])) st.lo[a] = st.hi[a] = 0.0f;  // no finite coordinate
}

// Per-thread scratch (keeps its capacity between calls): the candidates gathered for the current
// run, as x, y, z, r arrays of `cap` floats plus their slots, the pre-test flags, the sort keys,
// the slot ranges, and the handed-over pairs (target slot, source slot) found by this thread.
struct ThreadScratch {
  std::vector<float> g;
  std::vector<uint32_t> slot;
  std::vector<int32_t> pass;
  std::vector<uint64_t> keys;
  std::vector<uint32_t> ranges;
  std::vector<uint32_t> handed;
  std::vector<uint32_t> list;  // the current chunk's kept lists
  std::vector<uint32_t> orig;  // the original index of each gathered candidate
  size_t cap = 0, nhanded = 0;

  void reserve(size_t count) {
    if (count <= cap) return;
    cap = std::max<size_t>({count, 2 * cap, 256});
    g.resize(4 * cap);
    slot.resize(cap);
    orig.resize(cap);
    pass.resize(cap + 16);  // compaction stores whole 16-entry vectors
    keys.resize(cap + 8);   // and whole 8-key vectors
  }
  void reserve_handed(size_t more) {
    if (nhanded + more > handed.size()) handed.resize(std::max(2 * handed.size(), nhanded + more));
  }
};

ThreadScratch& thread_scratch() {
  thread_local ThreadScratch scratch;
  return scratch;
}

// Everything a query reads.
struct Searcher {
  const float *X, *Y, *Z, *R;  // sorted positions and radii
  const uint32_t* order;       // slot -> original index
  const uint32_t* start;       // cell starts (by key)
  const Grid* levels;
  int nlevels;
  float qs;
  bool multi;         // levels by radius: query own and larger levels, hand over across levels
  double reach_all;   // single level: the reach of every particle
  int K;
  bool prefilter;     // the float pre-test is safe (thresholds far from float underflow)
  bool uniform;       // one radius for all: the pre-test threshold is the constant uniform_pre
  float uniform_pre;  // t * t * kPreWiden for that radius

  void coords(const Grid& g, uint32_t k, double u[3]) const {
    u[0] = (double(X[k]) - g.lo[0]) * g.inv_h;
    u[1] = (double(Y[k]) - g.lo[1]) * g.inv_h;
    u[2] = (double(Z[k]) - g.lo[2]) * g.inv_h;
  }

  // Sets ts.ranges to the slot ranges that particles of level lq lying in the box [blo, bhi]
  // (grid coordinates of level lq) can pair with, in the levels they query.
  void collect(int lq, const double blo[3], const double bhi[3], ThreadScratch& ts) const {
    const Grid& gq = levels[lq];
    ts.ranges.clear();
    auto add = [&ts](uint32_t s0, uint32_t s1) {
      if (s1 <= s0) return;
      if (!ts.ranges.empty() && ts.ranges.back() == s0) ts.ranges.back() = s1;  // adjoining
      else ts.ranges.insert(ts.ranges.end(), {s0, s1});
    };
    for (int l = multi ? lq : 0; l < nlevels; ++l) {
      const Grid& g = levels[l];
      if (g.end == g.begin) continue;
      const double reach = multi ? double(qs) * (gq.rmax + g.rmax) : reach_all;
      const double du = reach * g.inv_h * (1.0 + kRelSlack) + kAbsSlack;
      double lo[3], hi[3];  // the box in this level's grid coordinates
      for (int a = 0; a < 3; ++a) {
        if (l == lq) {
          lo[a] = blo[a], hi[a] = bhi[a];
        } else {
          const double hq = 1.0 / gq.inv_h;
          lo[a] = (gq.lo[a] + blo[a] * hq - g.lo[a]) * g.inv_h;
          hi[a] = (gq.lo[a] + bhi[a] * hq - g.lo[a]) * g.inv_h;
        }
      }
      int64_t c0[3], c1[3];
      bool exact[3];  // stored cells are true cells along the axis (not a wrapped full window)
      for (int a = 0; a < 3; ++a) {
        c0[a] = cell_coord(lo[a] - du, g.ext[a]);
        c1[a] = cell_coord(hi[a] + du, g.ext[a]);
        exact[a] = true;
        // a window as wide as the stored period covers every residue exactly once
        if (c1[a] - c0[a] + 1 >= g.dim[a]) {
          exact[a] = g.dim[a] == g.ext[a];
          c0[a] = 0, c1[a] = g.dim[a] - 1;
        }
      }
      const int64_t rows = (c1[1] - c0[1] + 1) * (c1[2] - c0[2] + 1);
      if (2 * rows >= int64_t(g.end - g.begin)) {  // cheaper to take the whole level
        add(g.begin, g.end);
        continue;
      }
      // Rows of x cells; a row whose (y, z) slab lies beyond the reach of the box is skipped,
      // the others take only the x cells the widened box can touch within that slab.
      const double du2 = du * du;
      for (int64_t cz = c0[2]; cz <= c1[2]; ++cz) {
        const double ez = exact[2] ? gap(lo[2], hi[2], cz) : 0.0, rz = du2 - ez * ez;
        if (rz < 0.0) continue;
        for (int64_t cy = c0[1]; cy <= c1[1]; ++cy) {
          const double ey = exact[1] ? gap(lo[1], hi[1], cy) : 0.0, ryz = rz - ey * ey;
          if (ryz < 0.0) continue;
          const double w = std::sqrt(ryz);
          const int64_t x0 = cell_coord(lo[0] - w, g.ext[0]), x1 = cell_coord(hi[0] + w, g.ext[0]);
          const uint32_t row = g.key(0, cy, cz);
          const int64_t xlen = x1 - x0 + 1;
          if (xlen >= g.dim[0]) {
            add(start[row], start[row + g.dim[0]]);
            continue;
          }
          const int64_t xr = wrap(x0, g.dim[0]);
          const int64_t xa = std::min(xlen, g.dim[0] - xr), xb = xlen - xa;  // wrapped tail
          add(start[row + xr], start[row + xr + xa]);
          if (xb > 0) add(start[row], start[row + xb]);
        }
      }
    }
  }

  // Copies the slots of ts.ranges into the gather arrays; returns how many.
  uint32_t gather(ThreadScratch& ts) const {
    size_t count = 0;
    for (size_t r = 0; r < ts.ranges.size(); r += 2) count += ts.ranges[r + 1] - ts.ranges[r];
    ts.reserve(count);
    float *gx = ts.g.data(), *gy = gx + ts.cap, *gz = gy + ts.cap, *gr = gz + ts.cap;
    uint32_t* gs = ts.slot.data();
    uint32_t* go = ts.orig.data();
    uint32_t e = 0;
    for (size_t r = 0; r < ts.ranges.size(); r += 2)
      for (uint32_t s = ts.ranges[r]; s < ts.ranges[r + 1]; ++s, ++e) {
        gx[e] = X[s], gy[e] = Y[s], gz[e] = Z[s], gr[e] = R[s];
        gs[e] = s;
        go[e] = order[s];
      }
    return e;
  }

  // The partners of the particle in slot k among the `count` gathered candidates: sorted keys
  // in ts.keys, truncated to K. Partners in slots >= hand_from (larger levels) are also handed
  // over. Returns how many are kept; *found = how many passed before truncation.
  uint32_t test(uint32_t k, uint32_t count, uint32_t hand_from, ThreadScratch& ts,
                uint32_t* found) const {
    const float px = X[k], py = Y[k], pz = Z[k], pr = R[k];
    const float *gx = ts.g.data(), *gy = gx + ts.cap, *gz = gy + ts.cap, *gr = gz + ts.cap;
    const uint32_t* gs = ts.slot.data();
    int32_t* pass = ts.pass.data();
    if (hand_from == uint32_t(-1)) {
      // Nothing to hand over: every candidate takes the exact test in one loop the compiler
      // vectorises, then the keys that pass are compacted. The float pre-test and a scalar
      // exact test of its survivors had cost more than testing them all in vectors.
      const uint32_t* go = ts.orig.data();
      uint64_t* keys = ts.keys.data();
      for (uint32_t e = 0; e < count; ++e) {
        const double d2 = pair_dist2(px, py, pz, gx[e], gy[e], gz[e]);
        pass[e] = pair_ok(d2, qs, pr, gr[e]) & (gs[e] != k);
        keys[e] = pair_key(d2, go[e]);
      }
      uint32_t kept = 0;
#if defined(__AVX512F__) && defined(__AVX512VL__)
      // in place, 8 at a time (kept <= e: a store never reaches a key not yet read); keys has
      // 8 entries of slack for the last whole-vector store
      for (uint32_t e = 0; e < count; e += 8) {
        const __mmask8 live = count - e >= 8 ? __mmask8(0xFF) : __mmask8((1u << (count - e)) - 1);
        const __m256i f = _mm256_maskz_loadu_epi32(live, pass + e);
        const __mmask8 ok = _mm256_mask_test_epi32_mask(live, f, f);
        const __m512i kv = _mm512_maskz_loadu_epi64(live, keys + e);
        _mm512_storeu_si512(keys + kept, _mm512_maskz_compress_epi64(ok, kv));
        kept += uint32_t(std::popcount(unsigned(ok)));
      }
#else
      for (uint32_t e = 0; e < count; ++e) {
        keys[kept] = keys[e];
        kept += uint32_t(pass[e]);
      }
#endif
      *found = kept;
      return finish_candidates(keys, kept, K);
    }
    if (!prefilter) {
      for (uint32_t e = 0; e < count; ++e) pass[e] = 1;
    } else if (uniform) {  // vectorised
      for (uint32_t e = 0; e < count; ++e) {
        const float dx = px - gx[e], dy = py - gy[e], dz = pz - gz[e];
        pass[e] = dx * dx + dy * dy + dz * dz <= uniform_pre;
      }
    } else {
      for (uint32_t e = 0; e < count; ++e) {
        const float dx = px - gx[e], dy = py - gy[e], dz = pz - gz[e], t = qs * (pr + gr[e]);
        pass[e] = dx * dx + dy * dy + dz * dz <= t * t * kPreWiden;
      }
    }
    // Compact the survivors' entries (in place over pass: survivor m is entry e >= m), then
    // decide exactly. Neither loop branches on the outcome (acceptance is unpredictable).
    uint32_t* sel = reinterpret_cast<uint32_t*>(pass);
    uint32_t m = 0;
#if defined(__AVX512F__)
    // 16 entries at a time, compressed in a register and stored whole (pass has 16 entries of
    // slack); the scalar loop's dependence on m had taken 5% of a settled 100k pile's CPU
    __m512i idx = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    for (uint32_t e = 0; e < count; e += 16) {
      const __mmask16 live = count - e >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (count - e)) - 1);
      const __m512i pv = _mm512_maskz_loadu_epi32(live, pass + e);
      const __mmask16 ok = _mm512_mask_test_epi32_mask(live, pv, pv);
      _mm512_storeu_si512(sel + m, _mm512_maskz_compress_epi32(ok, idx));
      m += uint32_t(std::popcount(unsigned(ok)));
      idx = _mm512_add_epi32(idx, _mm512_set1_epi32(16));
    }
#else
    for (uint32_t e = 0; e < count; ++e) {  // every entry is written, the count advances or not
      const int32_t ok = pass[e];
      sel[m] = e;
      m += uint32_t(ok);
    }
#endif
    uint64_t* keys = ts.keys.data();
    uint32_t kept = 0;
    if (hand_from < uint32_t(-1)) {
      ts.reserve_handed(2 * size_t(m));
      uint32_t* hand = ts.handed.data();
      size_t nh = ts.nhanded;
      for (uint32_t a = 0; a < m; ++a) {
        const uint32_t e = sel[a], s = gs[e];
        const double d2 = pair_dist2(px, py, pz, gx[e], gy[e], gz[e]);
        const bool ok = pair_ok(d2, qs, pr, gr[e]) & (s != k);
        keys[kept] = pair_key(d2, order[s]);
        kept += ok;
        hand[nh] = s, hand[nh + 1] = k;
        nh += 2 * size_t(ok & (s >= hand_from));
      }
      ts.nhanded = nh;
    } else {
      for (uint32_t a = 0; a < m; ++a) {
        const uint32_t e = sel[a], s = gs[e];
        const double d2 = pair_dist2(px, py, pz, gx[e], gy[e], gz[e]);
        keys[kept] = pair_key(d2, order[s]);
        kept += pair_ok(d2, qs, pr, gr[e]) & (s != k);
      }
    }
    *found = kept;
    return finish_candidates(keys, kept, K);
  }
};

}  // namespace

void NeighborSearch::find(const float* P, const float* radius, size_t n, const NeighborQuery& q,
                          NeighborList& out, std::vector<uint32_t>* store) {
  out.offsets.resize(n + 1);
  out.offsets[0] = 0;
  if (n == 0) {
    out.indices.clear();
    return;
  }
  int T = q.threads > 0 ? q.threads : omp_get_max_threads();
  T = std::clamp(T, 1, kMaxThreads);
  T = int(std::min<size_t>(size_t(T), std::max<size_t>(1, n / 64)));

  // the cell keys, then the lists' store: the caller's buffer (all of its capacity) or ours
  std::vector<uint32_t>& buf = store ? *store : keys_;
  if (buf.size() < buf.capacity()) buf.resize(buf.capacity());
  const bool want_levels = !q.uniform_radius;
  Stats st;
  gather_stats(P, radius, n, T, want_levels, st);

  // Largest threshold t = qs * (ri + rj) any pair can have (float rounding is monotone).
  const float qs = q.query_scale;
  const bool any_radius = st.rmin <= st.rmax;  // false when every radius is NaN
  const float tmax =
      any_radius ? std::max(qs * (st.rmax + st.rmax), qs * (st.rmin + st.rmin)) : 0.0f;
  if (!(tmax > 0.0f)) {  // no pair can qualify
    std::fill(out.offsets.begin(), out.offsets.end(), 0u);
    out.indices.clear();
    return;
  }
  if (!std::isfinite(tmax)) {  // unbounded reach: every finite pair qualifies
    find_neighbors_brute(P, radius, n, q, out);
    return;
  }

  // Levels: one per float exponent of the radius when radii may differ (and qs > 0 with radii
  // >= 0, so that a level's reach is bounded by its largest radius); otherwise a single level
  // whose cells are as wide as the largest threshold.
  Grid levels[kBins];
  int bin_level[kBins];
  int nlevels = 0;
  const bool per_radius = qs > 0.0f && st.rmin >= 0.0f;
  const bool multi = want_levels && per_radius;
  if (multi) {
    int first = -1;
    for (int b = 0; b < kBins - 1; ++b)
      if (st.bin_count[b] > 0) {
        if (first < 0) first = b;
        bin_level[b] = nlevels;
        levels[nlevels].count = st.bin_count[b];
        levels[nlevels].rmax = st.bin_max[b];
        ++nlevels;
      }
    // radius 0 or NaN joins the smallest level (there is one: tmax > 0 needs a positive radius)
    bin_level[kBins - 1] = bin_level[first];
    levels[bin_level[first]].count += st.bin_count[kBins - 1];
  } else {
    nlevels = 1;
    levels[0].count = uint32_t(n);
    levels[0].rmax = st.rmax;
  }
  size_t total_keys = 0;
  for (int l = 0; l < nlevels; ++l) {
    Grid& g = levels[l];
    const double h = per_radius ? double(qs) * 2.0 * g.rmax : double(tmax);
    g.inv_h = 1.0 / h;
    for (int a = 0; a < 3; ++a) {
      // The origin sits a fraction of a cell below the box, so that lattices with spacings
      // in simple ratios to the cell size (grains sourced at separation 2r) do not put points
      // on cell walls, where the widened windows would take one more cell per axis.
      g.lo[a] = double(st.lo[a]) - kOriginShift * h;
      const double span = (double(st.hi[a]) - g.lo[a]) * g.inv_h;
      g.ext[a] = (span >= double(kCellMax) ? kCellMax : int64_t(span)) + 1;
    }
    choose_dims(g, g.count);
    g.key_base = uint32_t(total_keys);
    total_keys += g.cells();
  }

  // Keys, then a stable counting sort into cells (level-major, so every level is one slot range
  // and larger levels come later).
  if (buf.size() < n) buf.resize(n);
  resize_for_rewrite(order_, n);
  resize_for_rewrite(scratch_, 4 * n);
  const size_t chunk = std::max<size_t>(64, (n + 16 * size_t(T) - 1) / (16 * size_t(T)));
  const size_t nchunks = (n + chunk - 1) / chunk;
  // cell_start_: cell starts | chunk list positions | found per slot | handed group starts
  // | handed groups (sized once their total is known); the last two with levels only
  const size_t start_size = total_keys + 2, at_chunks = start_size, at_found = at_chunks + nchunks,
               at_groups = at_found + n, at_handed = at_groups + n + 2;
  const size_t start_need = multi ? at_handed : at_groups;
  resize_for_rewrite(cell_start_, start_need);
  uint32_t* keys = buf.data();
#pragma omp parallel for schedule(static) num_threads(T)
  for (ptrdiff_t i = 0; i < ptrdiff_t(n); ++i) {
    const Grid& g = multi ? levels[bin_level[radius_bin(radius[i])]] : levels[0];
    keys[i] = g.key_of(P + 3 * i);
  }
  uint32_t* cs = cell_start_.data();
  std::fill(cs, cs + start_size, 0u);
  for (size_t i = 0; i < n; ++i) ++cs[keys[i] + 2];
  for (size_t k = 2; k < start_size; ++k) cs[k] += cs[k - 1];
  uint32_t* order = order_.data();
  for (size_t i = 0; i < n; ++i) order[cs[keys[i] + 1]++] = uint32_t(i);
  // now cs[key] is the first slot of each key, cs[total_keys] == n
  for (int l = 0; l < nlevels; ++l) {
    levels[l].begin = cs[levels[l].key_base];
    levels[l].end = cs[levels[l].key_base + levels[l].cells()];
  }
  float *X = scratch_.data(), *Y = X + n, *Z = Y + n, *R = Z + n;
#pragma omp parallel for schedule(static) num_threads(T)
  for (ptrdiff_t k = 0; k < ptrdiff_t(n); ++k) {
    const size_t i = order[k];
    X[k] = P[3 * i + 0];
    Y[k] = P[3 * i + 1];
    Z[k] = P[3 * i + 2];
    R[k] = radius[i];
  }

  const int K = q.max_neighbors;
  Searcher S{X, Y, Z, R, order, cs, levels, nlevels, qs, multi, double(tmax), K, false, false, 0.0f};
  // The float pre-test needs every positive pair threshold well above float underflow: with
  // qs > 0 and radii >= 0 the smallest is qs * (smallest positive radius).
  S.prefilter = per_radius && double(qs) * double(st.rpos_min) > 1e-15;
  if (st.rmin == st.rmax && st.nan_radii == 0) {
    const float t = qs * (st.rmin + st.rmin);  // as in pair_ok
    S.uniform = true;
    S.uniform_pre = t * t * kPreWiden;
  }

  uint32_t* offsets = out.offsets.data();
  {
    // the lists' store: its contents (the cell keys) are spent, so a growth frees first
    const size_t per = K > 0 ? std::min<size_t>(size_t(K), 24) : 24;
    const size_t want = n * per + 1024;
    if (buf.size() < want) {
      std::vector<uint32_t>().swap(buf);
      buf.resize(want);
    }
  }
  size_t top = 0;  // the store's next free entry
  bool redo = false;
  auto kept_of = [K](uint32_t found) { return K > 0 ? std::min(found, uint32_t(K)) : found; };
#pragma omp parallel num_threads(T)
  {
    const double inf = std::numeric_limits<double>::infinity();
    ThreadScratch& ts = thread_scratch();
    uint32_t* chunk_pos = cell_start_.data() + at_chunks;
    uint32_t* found = cell_start_.data() + at_found;
    // 1. Queries. Consecutive slots in one cell form a run sharing one gather (the candidates
    // around the run's bounding box). A chunk's kept lists collect in the thread's scratch and
    // then take the next free range of the shared store (where is timing-dependent, but
    // only step 4 reads it, through chunk_pos); past the end the chunks keep counting, and the
    // pass is redone with room.
    for (;;) {
      const size_t cap = buf.size();
      ts.nhanded = 0;
#pragma omp for schedule(dynamic, 1)
      for (ptrdiff_t c = 0; c < ptrdiff_t(nchunks); ++c) {
        ts.list.clear();
        const uint32_t k0 = uint32_t(size_t(c) * chunk);
        const uint32_t k1 = uint32_t(std::min(n, size_t(c + 1) * chunk));
        int lq = 0;
        for (uint32_t k = k0; k < k1;) {
          while (k >= levels[lq].end) ++lq;
          const Grid& g = levels[lq];
          const uint32_t kend = std::min(k1, g.end);
          // The run: following slots in the same cell of the same level. Its box spans their
          // finite coordinates (a particle with a NaN or infinite one pairs with nothing).
          double u[3], lo[3], hi[3];
          S.coords(g, k, u);
          int64_t cell[3];
          for (int a = 0; a < 3; ++a) {
            cell[a] = cell_coord(u[a], g.ext[a]);
            lo[a] = std::isfinite(u[a]) ? u[a] : inf;
            hi[a] = std::isfinite(u[a]) ? u[a] : -inf;
          }
          uint32_t j = k + 1;
          for (; j < kend; ++j) {
            S.coords(g, j, u);
            if (cell_coord(u[0], g.ext[0]) != cell[0] || cell_coord(u[1], g.ext[1]) != cell[1] ||
                cell_coord(u[2], g.ext[2]) != cell[2])
              break;
            for (int a = 0; a < 3; ++a)
              if (std::isfinite(u[a])) lo[a] = std::min(lo[a], u[a]), hi[a] = std::max(hi[a], u[a]);
          }
          uint32_t count = 0;
          if (lo[0] <= hi[0] && lo[1] <= hi[1] && lo[2] <= hi[2]) {
            S.collect(lq, lo, hi, ts);
            count = S.gather(ts);
          }
          const uint32_t hand_from = multi && lq + 1 < nlevels ? g.end : uint32_t(-1);
          for (; k < j; ++k) {
            const uint32_t m = S.test(k, count, hand_from, ts, &found[k]);
            for (uint32_t e = 0; e < m; ++e) ts.list.push_back(uint32_t(ts.keys[e]));
          }
        }
        size_t pos;
#pragma omp atomic capture
        {
          pos = top;
          top += ts.list.size();
        }
        chunk_pos[c] = uint32_t(pos);
        // past cap: keep counting so the retry knows the size (an empty list may have no data)
        if (!ts.list.empty() && pos + ts.list.size() <= cap)
          std::memcpy(buf.data() + pos, ts.list.data(), ts.list.size() * sizeof(uint32_t));
      }
#pragma omp single
      {
        redo = top > cap;
        if (redo) {
          std::vector<uint32_t>().swap(buf);  // free first: the old lists are redone anyway
          buf.resize(top + top / 16 + 4096);
        }
        top = 0;
      }
      if (!redo) break;
    }

    // 2. Handed-over pairs, grouped by target slot with a counting sort. Counts are exact; the
    // order inside a group depends on timing, which the final sort of each list removes.
    if (multi) {
      uint32_t* gstart = cell_start_.data() + at_groups;
#pragma omp for schedule(static)
      for (ptrdiff_t k = 0; k < ptrdiff_t(n + 2); ++k) gstart[k] = 0;
      for (size_t h = 0; h < ts.nhanded; h += 2) {
#pragma omp atomic update
        ++gstart[ts.handed[h] + 2];
      }
#pragma omp barrier
#pragma omp single
      {
        for (size_t k = 2; k < n + 2; ++k) gstart[k] += gstart[k - 1];
        if (cell_start_.size() < at_handed + gstart[n + 1]) cell_start_.resize(at_handed + gstart[n + 1]);
      }
      gstart = cell_start_.data() + at_groups;
      uint32_t* groups = cell_start_.data() + at_handed;
      for (size_t h = 0; h < ts.nhanded; h += 2) {
        uint32_t at;
#pragma omp atomic capture
        at = gstart[ts.handed[h] + 1]++;
        groups[at] = ts.handed[h + 1];
      }
#pragma omp barrier
      // now group k is groups[gstart[k] .. gstart[k + 1])
    }

    // 3. Final counts, then offsets.
    {
      const uint32_t* base = cell_start_.data();
      const uint32_t *fnd = base + at_found, *gstart = base + at_groups;
#pragma omp for schedule(static)
      for (ptrdiff_t k = 0; k < ptrdiff_t(n); ++k) {
        const uint32_t handed = multi ? gstart[k + 1] - gstart[k] : 0;
        offsets[order[k] + 1] = kept_of(fnd[k] + handed);
      }
    }
#pragma omp single
    {
      for (size_t i = 0; i < n; ++i) offsets[i + 1] += offsets[i];
      // a plain resize, not resize_for_rewrite: freeing the old rows first and taking exactly
      // what they need ran settle_100k 4-6% slower in interleaved runs (the iterations, not the
      // allocation: its addresses against the sums' are the suspect), for 7 B a grain
      out.indices.resize(offsets[n]);
    }

    // 4. Each list to its place: a copy, or a merge with what was handed over (keys rebuilt
    // from the positions, exactly as the query made them).
    {
      const uint32_t* base = cell_start_.data();
      const uint32_t *cpos = base + at_chunks, *fnd = base + at_found, *gstart = base + at_groups,
                     *groups = multi ? base + at_handed : nullptr;
      uint32_t* dst = out.indices.data();
      const uint32_t* src = buf.data();
      // dynamic: the merges gather in the slots of the larger levels, at the end
#pragma omp for schedule(dynamic, 1)
      for (ptrdiff_t c = 0; c < ptrdiff_t(nchunks); ++c) {
        size_t pos = cpos[c];
        const size_t k1 = std::min(n, size_t(c + 1) * chunk);
        for (size_t k = size_t(c) * chunk; k < k1; ++k) {
          const uint32_t i = order[k], own = kept_of(fnd[k]);
          const uint32_t h0 = multi ? gstart[k] : 0, h1 = multi ? gstart[k + 1] : 0;
          if (h1 == h0) {
            if (own) std::memcpy(dst + offsets[i], src + pos, own * sizeof(uint32_t));
          } else {
            ts.reserve(own + (h1 - h0));
            uint64_t* mk = ts.keys.data();
            uint32_t m = 0;
            for (uint32_t e = 0; e < own; ++e) {
              const uint32_t o = src[pos + e];
              mk[m++] = pair_key(pair_dist2(X[k], Y[k], Z[k], P[3 * o], P[3 * o + 1], P[3 * o + 2]), o);
            }
            for (uint32_t h = h0; h < h1; ++h) {
              const uint32_t s = groups[h];
              mk[m++] = pair_key(pair_dist2(X[k], Y[k], Z[k], X[s], Y[s], Z[s]), order[s]);
            }
            m = finish_candidates(mk, m, K);
            for (uint32_t e = 0; e < m; ++e) dst[offsets[i] + e] = uint32_t(mk[e]);
          }
          pos += own;
        }
      }
    }
  }
}

void find_neighbors_brute(const float* P, const float* radius, size_t n, const NeighborQuery& q,
                          NeighborList& out) {
  out.offsets.assign(n + 1, 0u);
  out.indices.clear();
  std::vector<uint64_t> cand;
  for (size_t i = 0; i < n; ++i) {
    cand.clear();
    const float* a = P + 3 * i;
    for (size_t j = 0; j < n; ++j) {
      if (j == i) continue;
      const float* b = P + 3 * j;
      const double d2 = pair_dist2(a[0], a[1], a[2], b[0], b[1], b[2]);
      if (pair_ok(d2, q.query_scale, radius[i], radius[j])) cand.push_back(pair_key(d2, uint32_t(j)));
    }
    const uint32_t m = finish_candidates(cand.data(), uint32_t(cand.size()), q.max_neighbors);
    for (uint32_t e = 0; e < m; ++e) out.indices.push_back(uint32_t(cand[e]));
    out.offsets[i + 1] = uint32_t(out.indices.size());
  }
}

namespace {
// Spreads the low 21 bits of v so that two zero bits follow each.
inline uint64_t spread3(uint64_t v) {
  v &= 0x1fffff;
  v = (v | (v << 32)) & 0x1f00000000ffffull;
  v = (v | (v << 16)) & 0x1f0000ff0000ffull;
  v = (v | (v << 8)) & 0x100f00f00f00f00full;
  v = (v | (v << 4)) & 0x10c30c30c30c30c3ull;
  v = (v | (v << 2)) & 0x1249249249249249ull;
  return v;
}
}  // namespace

namespace {

// Stable LSD radix sort of order by code (codes of 3 * bits bits), 11 bits a pass.
template <class Code>
void radix_sort_by_code(std::vector<Code>& code, std::vector<uint32_t>& order, int bits) {
  const size_t n = code.size();
  std::vector<Code> code2(n);
  std::vector<uint32_t> order2(n);
  constexpr int kDigit = 11;
  std::vector<uint32_t> hist(size_t(1) << kDigit);
  for (int shift = 0; shift < 3 * bits; shift += kDigit) {
    std::fill(hist.begin(), hist.end(), 0u);
    const Code mask = (Code(1) << kDigit) - 1;
    for (size_t i = 0; i < n; ++i) ++hist[(code[i] >> shift) & mask];
    uint32_t sum = 0;
    for (auto& h : hist) {
      const uint32_t c = h;
      h = sum;
      sum += c;
    }
    for (size_t i = 0; i < n; ++i) {
      const uint32_t d = hist[(code[i] >> shift) & mask]++;
      code2[d] = code[i];
      order2[d] = order[i];
    }
    code.swap(code2);
    order.swap(order2);
  }
}

template <class Code>
void sort_by_morton(const float* P, const double* lo, const int64_t* ext, double inv, int bits,
                    std::vector<uint32_t>& order) {
  const size_t n = order.size();
  std::vector<Code> code(n);
#pragma omp parallel for schedule(static)
  for (ptrdiff_t i = 0; i < ptrdiff_t(n); ++i) {
    uint64_t c = 0;
    for (int a = 0; a < 3; ++a)
      c |= spread3(uint64_t(cell_coord((double(P[3 * i + a]) - lo[a]) * inv, ext[a]))) << a;
    code[i] = Code(c);
  }
  radix_sort_by_code(code, order, bits);
}

}  // namespace

// Morton code of each point's cell (21 bits per axis: a grid wider than 2^21 cells clamps its far
// cells onto the last one, which still gives a permutation), then a stable LSD radix sort, on
// 32-bit codes when they fit (grids up to 1024 cells a side: half the sort's memory).
std::vector<uint32_t> cell_sort_order(const float* P, size_t n, float cell) {
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  if (n < 2 || !(cell > 0.0f) || !std::isfinite(cell)) return order;
  const float inf = std::numeric_limits<float>::infinity();
  double lo[3];
  int64_t ext[3];
  for (int a = 0; a < 3; ++a) {
    float l = inf, h = -inf;
    for (size_t i = 0; i < n; ++i) {
      const float v = P[3 * i + a];
      if (std::isfinite(v)) l = std::min(l, v), h = std::max(h, v);
    }
    if (!(l <= h)) l = h = 0.0f;
    lo[a] = l;
    const double span = (double(h) - double(l)) / double(cell);
    ext[a] = int64_t(std::min(span, double((1 << 21) - 1))) + 1;  // 21 bits per axis
  }
  const int64_t widest = std::max({ext[0], ext[1], ext[2]});
  const int bits = int(std::bit_width(uint64_t(widest - 1)));
  if (bits == 0) return order;
  // stable: equal codes keep increasing index
  const double inv = 1.0 / double(cell);
  if (3 * bits <= 32)
    sort_by_morton<uint32_t>(P, lo, ext, inv, bits, order);
  else
    sort_by_morton<uint64_t>(P, lo, ext, inv, bits, order);
  return order;
}

}  // namespace grains
