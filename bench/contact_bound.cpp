// grains_contact_bound: how fast the contact iterations alone can run on one pile, as a floor
// under `grains-lab bench`'s particle-iterations per second.
//
//   grains_contact_bound FRAME.ply [--iterations N] [--repeat R] [--threads T]
//                        [--query-scale S] [--max-neighbors M]
//
// It reads a frame written by `grains run` (x y z and pscale; radii must be equal), orders the
// grains by cell as the grains node does, builds the neighbour rows with the solver's search
// (query scale 1.5, at most 32 neighbours: the node's defaults), and then times Jacobi iterations
// over those fixed rows with nothing else in the substep: no prediction, search, colliders,
// friction pass or velocity update. Three loops, each R x N iterations on T threads:
//
//   engine, with sums  the solver's own per-grain kernel (gr_iterate, kernels/iterate.h) as it
//                      runs for a pile without collider planes: contacts plus the per-entry
//                      overlap sums that bound the friction pass
//   engine, no sums    the same contact math (gr_gather_contacts_lanes) without the sums
//   ideal, with sums   (AVX-512 builds only) the same contact correction written directly with
//                      16-lane gathers, square root and division, and the per-entry sums
//
// It prints the pile's candidates and touching pairs per grain, the bytes per grain the rows and
// the sums need at that many candidates, and each loop's particle-iterations per second.
// Exit code 2 for bad arguments or an unreadable frame.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#if defined(__AVX512F__)
#include <immintrin.h>
#endif

#include "engine/geometry_io.h"
#include "engine/neighbors.h"
#include "nodes/grains/kernels/iterate.h"

namespace {

using Clock = std::chrono::steady_clock;

struct Options {
  std::string frame;
  int iterations = 20;
  int repeat = 10;
  int threads = 0;
  float query_scale = 1.5f;
  int max_neighbors = 32;
};

[[noreturn]] void usage(const char* why) {
  std::fprintf(stderr,
               "grains_contact_bound: %s\nusage: grains_contact_bound FRAME.ply [--iterations N] "
               "[--repeat R] [--threads T] [--query-scale S] [--max-neighbors M]\n",
               why);
  std::exit(2);
}

Options parse(int argc, char** argv) {
  Options o;
  for (int a = 1; a < argc; ++a) {
    std::string arg = argv[a];
    auto value = [&]() -> const char* {
      if (a + 1 >= argc) usage((arg + " needs a value").c_str());
      return argv[++a];
    };
    auto positive = [&](const char* text) {
      char* end = nullptr;
      long v = std::strtol(text, &end, 10);
      if (!end || *end || v <= 0 || v > 1000000) usage((arg + ": not a positive integer").c_str());
      return static_cast<int>(v);
    };
    if (arg == "--iterations") {
      o.iterations = positive(value());
    } else if (arg == "--repeat") {
      o.repeat = positive(value());
    } else if (arg == "--threads") {
      o.threads = positive(value());
    } else if (arg == "--max-neighbors") {
      o.max_neighbors = positive(value());
    } else if (arg == "--query-scale") {
      char* end = nullptr;
      o.query_scale = std::strtof(value(), &end);
      if (!end || *end || !(o.query_scale >= 1.0f && o.query_scale <= 4.0f))
        usage("--query-scale: a number in [1, 4]");
    } else if (!arg.empty() && arg[0] == '-') {
      usage(("unknown option " + arg).c_str());
    } else if (o.frame.empty()) {
      o.frame = arg;
    } else {
      usage("one frame only");
    }
  }
  if (o.frame.empty()) usage("no frame given");
  return o;
}

#if defined(__AVX512F__)
// sum of the 16 lanes (GCC 12 warns that _mm512_reduce_add_ps's halves may be uninitialised)
float lanes_sum(__m512 v) {
  const __m512d d = _mm512_castps_pd(v);
  const __m256 lo = _mm256_castpd_ps(_mm512_mask_extractf64x4_pd(_mm256_setzero_pd(), 0xF, d, 0));
  const __m256 hi = _mm256_castpd_ps(_mm512_mask_extractf64x4_pd(_mm256_setzero_pd(), 0xF, d, 1));
  const __m256 s8 = _mm256_add_ps(lo, hi);
  const __m128 s4 = _mm_add_ps(_mm256_castps256_ps128(s8), _mm256_extractf128_ps(s8, 1));
  const __m128 s2 = _mm_add_ps(s4, _mm_movehl_ps(s4, s4));
  return _mm_cvtss_f32(_mm_add_ss(s2, _mm_shuffle_ps(s2, s2, 1)));
}

// The contact correction of one grain over its row in blocks of 16 candidates (gathers), the
// per-entry overlaps scaled by 1 / count added to `sums`. The same law as the engine's loop
// (kernels/contact.h) for equal radii and masses: share 1/2, repulsion scale `repulse`.
void ideal_grain(const float* p, float* next, const uint32_t* off, const uint32_t* idx,
                 float* sums, float rsum, float repulse, long i) {
  const __m512 px = _mm512_set1_ps(p[3 * i]), py = _mm512_set1_ps(p[3 * i + 1]),
               pz = _mm512_set1_ps(p[3 * i + 2]);
  const __m512 rs = _mm512_set1_ps(rsum), rs2 = _mm512_set1_ps(rsum * rsum);
  const __m512 scale = _mm512_set1_ps(0.5f * repulse);
  __m512 sx = _mm512_setzero_ps(), sy = sx, sz = sx, sc = sx;
  const uint32_t b = off[i], e = off[i + 1];
  alignas(64) float overlap[64 + 16];
  for (uint32_t k = b; k < e; k += 16) {
    const __mmask16 live = e - k >= 16 ? __mmask16(0xffff) : __mmask16((1u << (e - k)) - 1);
    const __m512i j = _mm512_maskz_loadu_epi32(live, idx + k);
    const __m512i j3 = _mm512_add_epi32(_mm512_add_epi32(j, j), j);
    const __m512 qx = _mm512_mask_i32gather_ps(px, live, j3, p, 4);
    const __m512 qy = _mm512_mask_i32gather_ps(py, live, j3, p + 1, 4);
    const __m512 qz = _mm512_mask_i32gather_ps(pz, live, j3, p + 2, 4);
    const __m512 dx = _mm512_sub_ps(px, qx), dy = _mm512_sub_ps(py, qy), dz = _mm512_sub_ps(pz, qz);
    const __m512 d2 = _mm512_fmadd_ps(dx, dx, _mm512_fmadd_ps(dy, dy, _mm512_mul_ps(dz, dz)));
    const __mmask16 touch = _mm512_mask_cmp_ps_mask(live, d2, rs2, _CMP_LT_OQ) &
                            _mm512_cmpneq_epi32_mask(j, _mm512_set1_epi32(int(i)));
    const __m512 dist = _mm512_maskz_sqrt_ps(touch, d2);
    const __m512 d = _mm512_maskz_sub_ps(touch, rs, dist);
    const __m512 along = _mm512_maskz_div_ps(touch, _mm512_mul_ps(d, scale), dist);
    sx = _mm512_fmadd_ps(along, dx, sx);
    sy = _mm512_fmadd_ps(along, dy, sy);
    sz = _mm512_fmadd_ps(along, dz, sz);
    sc = _mm512_add_ps(sc, _mm512_maskz_mov_ps(touch, _mm512_set1_ps(1.0f)));
    _mm512_store_ps(overlap + (k - b), d);
  }
  const float count = lanes_sum(sc);
  const float share = count > 0 ? 1.0f / count : 0.0f;
  for (uint32_t k = b; k < e; ++k) sums[k] += overlap[k - b] * share;
  next[3 * i] = p[3 * i] + lanes_sum(sx) * share;
  next[3 * i + 1] = p[3 * i + 1] + lanes_sum(sy) * share;
  next[3 * i + 2] = p[3 * i + 2] + lanes_sum(sz) * share;
}
#endif

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  grains::ParticleStore pts;
  try {
    pts = grains::read_ply(o.frame);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "grains_contact_bound: %s\n", e.what());
    return 2;
  }
  const size_t n = pts.size();
  const float* P_in = pts.v3_if("P");
  const float* r_in = pts.f_if("pscale");
  if (n < 2 || !P_in || !r_in) {
    std::fprintf(stderr, "grains_contact_bound: %s: needs at least 2 points with pscale\n",
                 o.frame.c_str());
    return 2;
  }
  const float r = r_in[0];
  for (size_t i = 0; i < n; ++i)
    if (r_in[i] != r || !(r > 0)) {
      std::fprintf(stderr, "grains_contact_bound: %s: radii must be equal and positive (point %zu)\n",
                   o.frame.c_str(), i);
      return 2;
    }
  const int threads = o.threads > 0 ? o.threads : omp_get_max_threads();

  // the grains node's order (cell-sorted) and the solver's rows
  const std::vector<uint32_t> order = grains::cell_sort_order(P_in, n, 2.0f * r * o.query_scale);
  std::vector<float> P(3 * n + 1, 0.0f), radius(n, r), inv_mass(n, 1.0f);
  for (size_t k = 0; k < n; ++k)
    for (int a = 0; a < 3; ++a) P[3 * k + a] = P_in[3 * order[k] + a];
  grains::NeighborSearch search;
  grains::NeighborList rows;
  grains::NeighborQuery q;
  q.query_scale = o.query_scale;
  q.max_neighbors = o.max_neighbors;
  q.uniform_radius = true;
  q.threads = threads;
  search.find(P.data(), radius.data(), n, q, rows);
  const size_t entries = rows.indices.size();
  size_t touching = 0, longest = 0;
  for (size_t i = 0; i < n; ++i) {
    longest = std::max<size_t>(longest, rows.count(i));
    for (uint32_t k = rows.offsets[i]; k < rows.offsets[i + 1]; ++k) {
      const uint32_t j = rows.indices[k];
      const float dx = P[3 * i] - P[3 * j], dy = P[3 * i + 1] - P[3 * j + 1],
                  dz = P[3 * i + 2] - P[3 * j + 2];
      touching += j != i && dx * dx + dy * dy + dz * dz < 4 * r * r;
    }
  }
  std::printf("frame %s: %zu grains, radius %g m\n", o.frame.c_str(), n, double(r));
  std::printf("rows (query scale %g, at most %d): %.2f candidates per grain, %.2f touching\n",
              double(o.query_scale), o.max_neighbors, double(entries) / double(n),
              double(touching) / double(n));
  std::printf("rows + friction sums at that size: %.0f B/grain (4 B index + 4 B sum per entry)\n",
              8.0 * double(entries) / double(n));

  // the kernel inputs as the solver fills them for equal grains with no collider planes
  gr_grains g;
  std::memset(&g, 0, sizeof g);
  g.P = P.data();
  g.radius = radius.data();
  g.inv_mass = inv_mass.data();
  g.uniform_radius = r;
  g.uniform_inv_mass = 1.0f;
  g.nbr_offsets = rows.offsets.data();
  g.nbr_indices = rows.indices.data();
  gr_params prm;
  std::memset(&prm, 0, sizeof prm);
  prm.internal_collisions_weight = 1.0f;
  prm.internal_collisions_stiffness = 1000.0f;
  prm.stiffness_denominator = float(o.iterations);
  prm.over_relaxation = 1.0f;
  prm.neighbor_query_scale = o.query_scale;
  prm.friction_with_particles = 1.0f;
  const float repulse = gr_repulsion_scale(&g, &prm, 0);

  const size_t row_length = (std::max<size_t>(longest, 1) + GR_LANES - 1) / GR_LANES * GR_LANES;
  const size_t row_stride = (row_length + 15) / 16 * 16 + 16;
  std::vector<float> scratch(row_stride * size_t(threads));
  std::vector<uint32_t> sums(entries + 16, 0u);
  const long ln = static_cast<long>(n);

  // one loop: R x N iterations from the frame's positions; returns particle-iterations per second
  auto time_loop = [&](int variant) {
    std::vector<float> p(P), next(P);
    std::fill(sums.begin(), sums.end(), 0u);
    const auto t0 = Clock::now();
    for (int rep = 0; rep < o.repeat; ++rep)
      for (int it = 0; it < o.iterations; ++it) {
        const float* pp = p.data();
        float* nx = next.data();
#pragma omp parallel num_threads(threads)
        {
          gr_normal_sums acc{nullptr, nullptr, nullptr, nullptr, nullptr};
          if (variant == 0) {
            acc.pair_iteration = scratch.data() + row_stride * size_t(omp_get_thread_num());
            acc.pair = sums.data();
          }
#pragma omp for schedule(static)
          for (long i = 0; i < ln; ++i) {
            const int ii = static_cast<int>(i);
            if (variant == 2) {
#if defined(__AVX512F__)
              ideal_grain(pp, nx, rows.offsets.data(), rows.indices.data(),
                          reinterpret_cast<float*>(sums.data()), 2 * r, repulse, i);
#endif
              continue;
            }
            gr_float3 x;
            if (variant == 0) {
              x = gr_iterate(&g, &prm, pp, ii, &acc);
            } else {
              gr_float3 sum = gr_make3(0.0f, 0.0f, 0.0f);
              const int count = gr_gather_contacts_lanes(&g, pp, ii, repulse, nullptr, &sum, 1);
              x = gr_average(gr_load3(pp, ii), sum, count, 1.0f, 0);
            }
            gr_store3(nx, ii, x);
          }
        }
        p.swap(next);
      }
    const double s = std::chrono::duration<double>(Clock::now() - t0).count();
    return double(n) * o.iterations * o.repeat / s;
  };
  std::printf("%d x %d iterations on %d threads, particle-iterations per second:\n", o.repeat,
              o.iterations, threads);
  std::printf("  engine, with sums  %.3g M\n", time_loop(0) / 1e6);
  std::printf("  engine, no sums    %.3g M\n", time_loop(1) / 1e6);
#if defined(__AVX512F__)
  if (longest <= 64)
    std::printf("  ideal, with sums   %.3g M\n", time_loop(2) / 1e6);
  else
    std::printf("  ideal, with sums   (rows of at most 64 only)\n");
#else
  std::printf("  ideal, with sums   (needs an AVX-512 build)\n");
#endif
  return 0;
}
