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
/* the device has double precision, which the program's rows, rigid shapes, mesh queries,
 * sleeping test and motion measure need (GR_NO_FP64: built as for a device without it,
 * GRAINS_OPENCL_NO_FP64=1, opencl/device.cpp) */
#if defined(cl_khr_fp64) && !defined(GR_NO_FP64)
#define GR_DOUBLES 1
#endif
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

/* The contact loop's 8-lane block operations (gr_gather_contacts_lanes): the positions of 8
 * grains j[0..7] of an (n x 3) array into x, y, z (gr_load_block), a row of per-entry sums
 * (gr_add_block), and, where a vector version exists, a block's lanes summed (gr_sum_lanes).
 * The portable versions below are what OpenCL compiles; on an x86 CPU with AVX2 and FMA the
 * CPU-only header nodes/grains/cpu/blocks_avx2.h gives the same results with vector
 * instructions (a test compares the two, GR_PORTABLE_LOADS). */
#if !defined(GR_OPENCL) && defined(__AVX2__) && defined(__FMA__) && !defined(GR_PORTABLE_LOADS)
#include "../cpu/blocks_avx2.h"
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
/* a + s * b with one rounding a component (fused), on every backend: where the host and a
 * device must make the same floats (the prediction, which both make), whether or not a compiler
 * would fuse the multiply and the add of gr_madd */
#ifdef GR_OPENCL
GR_INLINE gr_float3 gr_fmadd(gr_float3 a, gr_float3 b, float s) {
  return fma(b, (float3)(s), a);
}
#else
GR_INLINE gr_float3 gr_fmadd(gr_float3 a, gr_float3 b, float s) {
  return gr_make3(fmaf(b.x, s, a.x), fmaf(b.y, s, a.y), fmaf(b.z, s, a.z));
}
#endif
/* a point attribute that scales a parameter: missing (null) = 1 */
GR_INLINE float gr_attr(const GR_GLOBAL float* a, int i) { return a ? a[i] : 1.0f; }

#endif /* GRAINS_KERNELS_PRELUDE_H */
