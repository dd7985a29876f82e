/* The neighbour pair test and the order of a neighbour row, one definition for the CPU search
 * (engine/neighbors.cpp) and the OpenCL one (nodes/grains/kernels/grid.h, which a device
 * compiles from this same file): a row found on either is the same list, bit for bit.
 *
 * gr_pair_dist2: the float differences of the two positions, squared and summed in double.
 * Every product of two floats is exact in double, so the sum does not depend on whether a
 * compiler fuses a multiply and an add. gr_pair_ok: a pair when d2 < t^2 with
 * t = qs (ri + rj) rounded to float, compared in double; none when t <= 0 or NaN.
 * gr_pair_key: a row is ordered by distance (d2 rounded to float: its bits are monotone for
 * non-negative values), then by the other grain's index, so every key of a row is unique.
 *
 * Written in the subset common to C, C++ and OpenCL C; the OpenCL side needs cl_khr_fp64. */
#ifndef GRAINS_ENGINE_PAIR_TEST_H
#define GRAINS_ENGINE_PAIR_TEST_H

#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)
typedef ulong gr_pair_key_t;
static inline uint gr_pair_float_bits(float f) {
  return as_uint(f);
}
#else
#include <stdint.h>
#include <string.h>
typedef uint64_t gr_pair_key_t;
static inline uint32_t gr_pair_float_bits(float f) {
  uint32_t u;
  memcpy(&u, &f, sizeof u);
  return u;
}
#endif

/* squared distance of a (the grain whose row is built) and b */
static inline double gr_pair_dist2(float ax, float ay, float az, float bx, float by, float bz) {
  const double dx = (double)(ax - bx), dy = (double)(ay - by), dz = (double)(az - bz);
  return dx * dx + dy * dy + dz * dz;
}

/* 1 when the grains of radii ri, rj at squared distance d2 are neighbours at query scale qs */
static inline int gr_pair_ok(double d2, float qs, float ri, float rj) {
  const float t = qs * (ri + rj);
  return (t > 0.0f) & (d2 < (double)t * (double)t);
}

/* a row's sort key of the grain j at squared distance d2 */
static inline gr_pair_key_t gr_pair_key(double d2, unsigned int j) {
  return ((gr_pair_key_t)gr_pair_float_bits((float)d2) << 32) | (gr_pair_key_t)j;
}

#endif
