/* Prelude shared by the grains kernels: qualifiers, a 3-vector and math names for C++ (the CPU
 * backend) and OpenCL C (a thin __kernel per header). Everything below is the common subset of
 * C and OpenCL C: no references, templates, std:: or C++ casts.
 *
 * Math goes through gr_sqrt / gr_exp / gr_min / gr_max because OpenCL C spells them sqrt, exp,
 * fmin, fmax (overloaded) while C spells the float versions sqrtf, expf, fminf, fmaxf. */
#ifndef GRAINS_KERNELS_PRELUDE_H
#define GRAINS_KERNELS_PRELUDE_H

#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)

#define GR_OPENCL 1 /* compiled as OpenCL C (nodes/grains/opencl/grains.cl) */
#define GR_GLOBAL __global
#define GR_INLINE static inline
#define GR_HOT static inline
typedef float3 gr_float3;
typedef uint gr_uint;
#define gr_sqrt(x) sqrt(x)
#define gr_exp(x) exp(x)
#define gr_min(a, b) fmin((a), (b))
#define gr_max(a, b) fmax((a), (b))
#define GR_NULL 0

GR_INLINE gr_float3 gr_make3(float x, float y, float z) { return (float3)(x, y, z); }
GR_INLINE gr_float3 gr_add(gr_float3 a, gr_float3 b) { return a + b; }
GR_INLINE gr_float3 gr_sub(gr_float3 a, gr_float3 b) { return a - b; }
GR_INLINE gr_float3 gr_scale(gr_float3 a, float s) { return a * s; }
GR_INLINE float gr_dot(gr_float3 a, gr_float3 b) { return dot(a, b); }
GR_INLINE gr_float3 gr_load3(const __global float* a, int i) { return vload3(i, a); }
GR_INLINE void gr_store3(__global float* a, int i, gr_float3 v) { vstore3(v, i, a); }
#define gr_as_float(u) as_float(u)
#define gr_as_uint(f) as_uint(f)

#else /* C / C++ */

#include <math.h>

#define GR_GLOBAL
#define GR_INLINE static inline
/* the innermost loops: inlined into their caller, where they are vectorised */
#define GR_HOT static inline __attribute__((always_inline))
typedef struct {
  float x, y, z;
} gr_float3;
typedef unsigned int gr_uint;
#define gr_sqrt(x) sqrtf(x)
#define gr_exp(x) expf(x)
/* comparisons, not fminf/fmaxf: those are library calls unless NaNs are ruled out */
#define gr_min(a, b) gr_minf((a), (b))
#define gr_max(a, b) gr_maxf((a), (b))
#define GR_NULL 0

GR_INLINE float gr_minf(float a, float b) { return b < a ? b : a; }
GR_INLINE float gr_maxf(float a, float b) { return b > a ? b : a; }

GR_INLINE gr_float3 gr_make3(float x, float y, float z) {
  gr_float3 r;
  r.x = x;
  r.y = y;
  r.z = z;
  return r;
}
GR_INLINE gr_float3 gr_add(gr_float3 a, gr_float3 b) { return gr_make3(a.x + b.x, a.y + b.y, a.z + b.z); }
GR_INLINE gr_float3 gr_sub(gr_float3 a, gr_float3 b) { return gr_make3(a.x - b.x, a.y - b.y, a.z - b.z); }
GR_INLINE gr_float3 gr_scale(gr_float3 a, float s) { return gr_make3(a.x * s, a.y * s, a.z * s); }
GR_INLINE float gr_dot(gr_float3 a, gr_float3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
GR_INLINE gr_float3 gr_load3(const float* a, int i) {
  return gr_make3(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
}
GR_INLINE void gr_store3(float* a, int i, gr_float3 v) {
  a[3 * i] = v.x;
  a[3 * i + 1] = v.y;
  a[3 * i + 2] = v.z;
}
/* a float kept as its bits in unsigned storage (OpenCL's as_float / as_uint) */
GR_INLINE float gr_as_float(gr_uint u) { return __builtin_bit_cast(float, u); }
GR_INLINE gr_uint gr_as_uint(float f) { return __builtin_bit_cast(gr_uint, f); }

#endif

/* the positions of 8 grains j[0..7] of (n x 3) array a into x, y, z (gr_gather_contacts_lanes) */
#if !defined(GR_OPENCL) && defined(__AVX2__) && \
    defined(__FMA__) && !defined(GR_PORTABLE_LOADS) /* (a test compares the two) */
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
#else
GR_INLINE void gr_add_block(GR_GLOBAL gr_uint* sum, const GR_GLOBAL float* add, float s) {
  int l;
  for (l = 0; l < 8; ++l) sum[l] = gr_as_uint(gr_as_float(sum[l]) + add[l] * s);
}
GR_INLINE void gr_load_block(const GR_GLOBAL float* a, const gr_uint* j, float* x, float* y, float* z) {
  int l;
  for (l = 0; l < 8; ++l) {
    x[l] = a[3 * j[l]];
    y[l] = a[3 * j[l] + 1];
    z[l] = a[3 * j[l] + 2];
  }
}
#endif

GR_INLINE float gr_length(gr_float3 a) { return gr_sqrt(gr_dot(a, a)); }
/* a + s * b */
GR_INLINE gr_float3 gr_madd(gr_float3 a, gr_float3 b, float s) { return gr_add(a, gr_scale(b, s)); }
/* a point attribute that scales a parameter: missing (null) = 1 */
GR_INLINE float gr_attr(const GR_GLOBAL float* a, int i) { return a ? a[i] : 1.0f; }

#endif /* GRAINS_KERNELS_PRELUDE_H */
