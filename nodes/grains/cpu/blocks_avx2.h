/* AVX2 versions of the contact loop's block operations (kernels/prelude.h), for the CPU path
 * only: the OpenCL compiler never reads this file, and the kernels never name an intrinsic.
 * Each gives the same floats as the portable version it replaces. */
#ifndef GRAINS_CPU_BLOCKS_AVX2_H
#define GRAINS_CPU_BLOCKS_AVX2_H
#include <immintrin.h>
/* AVX2: one 4-float load per grain (reads a[3 j + 3]: a holds 3 n + 1 floats) and a transpose,
 * instead of three 8-lane gathers */
GR_INLINE void gr_load_block(const float* a, const gr_uint* j, float* x, float* y, float* z) {
  __m256 r0 = _mm256_set_m128(_mm_loadu_ps(a + 3 * j[4]), _mm_loadu_ps(a + 3 * j[0]));
  __m256 r1 = _mm256_set_m128(_mm_loadu_ps(a + 3 * j[5]), _mm_loadu_ps(a + 3 * j[1]));
  __m256 r2 = _mm256_set_m128(_mm_loadu_ps(a + 3 * j[6]), _mm_loadu_ps(a + 3 * j[2]));
  __m256 r3 = _mm256_set_m128(_mm_loadu_ps(a + 3 * j[7]), _mm_loadu_ps(a + 3 * j[3]));
  __m256 t0 = _mm256_unpacklo_ps(r0, r1); /* x0 x1 y0 y1 | x4 x5 y4 y5 */
  __m256 t1 = _mm256_unpackhi_ps(r0, r1); /* z0 z1 .. .. | z4 z5 .. .. */
  __m256 t2 = _mm256_unpacklo_ps(r2, r3); /* x2 x3 y2 y3 | x6 x7 y6 y7 */
  __m256 t3 = _mm256_unpackhi_ps(r2, r3); /* z2 z3 .. .. | z6 z7 .. .. */
  __m256 vx = _mm256_shuffle_ps(t0, t2, 0x44); /* x0 x1 x2 x3 | x4 x5 x6 x7 */
  __m256 vy = _mm256_shuffle_ps(t0, t2, 0xEE);
  __m256 vz = _mm256_shuffle_ps(t1, t3, 0x44);
  _mm256_storeu_ps(x, vx);
  _mm256_storeu_ps(y, vy);
  _mm256_storeu_ps(z, vz);
}
/* (x, y, z, c) += the lanes of x[0..7], y, z, c, added lane after lane from lane 0 (the order
 * the portable loop adds them in, so the sums are the same floats): a transpose gives each lane's
 * four values as one vector, then eight vector adds (the scalar loop had reloaded the 32 values
 * from the stack one by one) */
#define GR_HAVE_SUM_LANES 1
GR_INLINE void gr_sum_lanes(const float* x, const float* y, const float* z, const float* c,
                            float* out) {
  const __m256 vx = _mm256_loadu_ps(x), vy = _mm256_loadu_ps(y), vz = _mm256_loadu_ps(z),
               vc = _mm256_loadu_ps(c);
  const __m256 t0 = _mm256_unpacklo_ps(vx, vy); /* x0 y0 x1 y1 | x4 y4 x5 y5 */
  const __m256 t1 = _mm256_unpackhi_ps(vx, vy); /* x2 y2 x3 y3 | x6 y6 x7 y7 */
  const __m256 t2 = _mm256_unpacklo_ps(vz, vc); /* z0 c0 z1 c1 | z4 c4 z5 c5 */
  const __m256 t3 = _mm256_unpackhi_ps(vz, vc); /* z2 c2 z3 c3 | z6 c6 z7 c7 */
  const __m256 l04 = _mm256_shuffle_ps(t0, t2, 0x44); /* lane 0 | lane 4 */
  const __m256 l15 = _mm256_shuffle_ps(t0, t2, 0xEE); /* lane 1 | lane 5 */
  const __m256 l26 = _mm256_shuffle_ps(t1, t3, 0x44); /* lane 2 | lane 6 */
  const __m256 l37 = _mm256_shuffle_ps(t1, t3, 0xEE); /* lane 3 | lane 7 */
  __m128 s = _mm_setzero_ps();
  s = _mm_add_ps(s, _mm256_castps256_ps128(l04));
  s = _mm_add_ps(s, _mm256_castps256_ps128(l15));
  s = _mm_add_ps(s, _mm256_castps256_ps128(l26));
  s = _mm_add_ps(s, _mm256_castps256_ps128(l37));
  s = _mm_add_ps(s, _mm256_extractf128_ps(l04, 1));
  s = _mm_add_ps(s, _mm256_extractf128_ps(l15, 1));
  s = _mm_add_ps(s, _mm256_extractf128_ps(l26, 1));
  s = _mm_add_ps(s, _mm256_extractf128_ps(l37, 1));
  _mm_storeu_ps(out, s);
}
/* sum[0..7] += add[0..7] * s, sum as float bits (the friction pass's per-entry sums) */
GR_INLINE void gr_add_block(gr_uint* sum, const float* add, float s) {
  const __m256 v = _mm256_loadu_ps((const float*)sum);
  _mm256_storeu_ps((float*)sum, _mm256_fmadd_ps(_mm256_loadu_ps(add), _mm256_set1_ps(s), v));
}

#endif /* GRAINS_CPU_BLOCKS_AVX2_H */
