/* Error control's motion measure (engine/motion.cpp, motion_substeps), grain by grain: one
 * definition for the CPU and an OpenCL device (the grains node's ends held there,
 * nodes/grains/opencl/grains.cl, which compiles this same file with cl_khr_fp64).
 *
 * A grain of radius r moving at |v| with acceleration a = |F| / m may cover `step` r in one
 * substep: the substeps S a frame (fps) with |v| / (fps S) + a / (fps S)^2 = step r, the
 * positive root in 1 / (fps S). A resting grain's fall in one substep, a / (fps S)^2, is bounded
 * by the caller from the largest a / r.
 *
 * Both sides take the same operations in the same order (the lengths in float, the rest in
 * double), the device's division and square root correctly rounded, and neither fuses a
 * multiply and an add: each function opens with GR_MOTION_EXACT (the device's FP_CONTRACT off)
 * and the host compiles its caller without contraction (engine/motion.cpp, -ffp-contract=off in
 * CMakeLists.txt). The maxima are the same in any order: a device finds the CPU's, bit for bit.
 *
 * Written in the subset common to C, C++ and OpenCL C. */
#ifndef GRAINS_ENGINE_MOTION_NEED_H
#define GRAINS_ENGINE_MOTION_NEED_H

#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)
#define GR_MOTION_SQRTF(x) sqrt(x)
#define GR_MOTION_SQRT(x) sqrt(x)
#define GR_MOTION_FINITE(x) isfinite(x)
#define GR_MOTION_EXACT _Pragma("OPENCL FP_CONTRACT OFF")
#else
#include <math.h>
#define GR_MOTION_SQRTF(x) sqrtf(x)
#define GR_MOTION_SQRT(x) sqrt(x)
#define GR_MOTION_FINITE(x) isfinite(x)
#define GR_MOTION_EXACT
#endif

/* |(x, y, z)|, written out */
static inline float gr_motion_length(float x, float y, float z) {
  GR_MOTION_EXACT
  return GR_MOTION_SQRTF(x * x + y * y + z * z);
}

/* a grain's acceleration |F| / m (0 without a mass) */
static inline float gr_motion_acc(float fx, float fy, float fz, float m) {
  GR_MOTION_EXACT
  return m > 0 ? gr_motion_length(fx, fy, fz) / m : 0.0f;
}

/* One grain (velocity v, acceleration acc, radius r) into the measure: *worst, the substeps a
 * frame its motion needs, at least what it holds; *fall, the largest acc / r. A grain without
 * a radius, or whose root is not a finite positive number (at rest without force), adds
 * nothing. */
static inline void gr_motion_need(float vx, float vy, float vz, float acc, float r, double step,
                                  double fps, double* worst, double* fall) {
  GR_MOTION_EXACT
  const double reach = step * r;
  const double a = acc;
  double speed, x, need, drop;
  if (!(reach > 0)) return;
  speed = gr_motion_length(vx, vy, vz);
  x = a > 0 ? (-speed + GR_MOTION_SQRT(speed * speed + 4.0 * a * reach)) / (2.0 * a)
            : (speed > 0 ? reach / speed : 0.0);
  if (!(x > 0) || !GR_MOTION_FINITE(x)) return;
  need = 1.0 / (fps * x);
  drop = a / r;
  if (*worst < need) *worst = need;
  if (*fall < drop) *fall = drop;
}

#endif /* GRAINS_ENGINE_MOTION_NEED_H */
