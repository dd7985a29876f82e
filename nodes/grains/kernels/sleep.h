/* The grains node's sleeping test (DESIGN §4; nodes/grains/grains_node.cpp, put_to_sleep and
 * update_sleep), grain by grain: the host runs these functions through
 * nodes/grains/sleep_rows.cpp, a device through opencl/grains.cl (gr_k_sleep_begin,
 * gr_k_sleep_settle, gr_k_sleep_update), and both decide alike, bit for bit: every length is
 * written out without a multiply and an add fused (the device's FP_CONTRACT off here, the
 * host's file compiled with -ffp-contract=off) and without OpenCL's dot(), whose order a device
 * chooses.
 *
 * Speeds are in grain radii a second. A grain's stay (`time`, from `anchor`) counts while it
 * keeps within stay x r of where it began; at sleep_time it falls asleep: for the next substeps
 * it is a fixed grain (mass 0, v 0) that ends each where it began, until something wakes it. */
#ifndef GRAINS_KERNELS_SLEEP_H
#define GRAINS_KERNELS_SLEEP_H
#include "row_stats.h"
/* the device's program holds engine/collider_shape.h beside the kernel headers */
#if defined(GR_OPENCL)
#include "collider_shape.h"
#else
#include "engine/collider_shape.h"
#endif

typedef struct {
  float dt;         /* the substep (s) */
  float sleep_time; /* s */
  float stay;       /* sleep_speed x sleep_time: radii */
  float wake;       /* 4 x sleep_speed: radii a second */
} gr_sleep_params;

/* The test's arrays, n grains in the solver's order. */
typedef struct {
  /* carried from substep to substep (the node's point attributes): how long (s) each grain has
   * stayed, where its stay began (x3), its force / mass when it fell asleep (x3) and how many
   * grains touched it then */
  GR_GLOBAL float* time;
  GR_GLOBAL float* anchor;
  GR_GLOBAL float* accel;
  GR_GLOBAL int* contacts;
  /* this substep's: whether a grain may sleep (null: every one; a pinned grain may not), its
   * mass awake, radius and force (force_index: grain k's is force[force_index[k]], null: k;
   * force_uniform: every grain's is force[0]), its start (world, x3) and start velocity (x3) */
  const GR_GLOBAL unsigned char* can;
  const GR_GLOBAL float* mass;
  const GR_GLOBAL float* radius;
  const GR_GLOBAL float* force;
  const GR_GLOBAL gr_uint* force_index;
  int force_uniform;
  const GR_GLOBAL float* start;
  const GR_GLOBAL float* start_v;
  /* what the stages write: whether a grain sleeps this substep, whether the end woke it, and
   * whether it is an awake grain fast enough to wake a sleeper it touches */
  GR_GLOBAL unsigned char* asleep;
  GR_GLOBAL unsigned char* woken;
  GR_GLOBAL unsigned char* fast;
} gr_sleep;

GR_INLINE float gr_sleep_length(float x, float y, float z) {
  GR_ROW_EXACT
  return gr_sqrt(x * x + y * y + z * z);
}

GR_INLINE gr_float3 gr_sleep_force(const gr_sleep* s, int k) {
  if (!s->force) return gr_make3(0.0f, 0.0f, 0.0f);
  return gr_load3(s->force, s->force_uniform ? 0 : (s->force_index ? (int)s->force_index[k] : k));
}

/* whether grain k may sleep: a mass, no pin */
GR_INLINE int gr_sleep_can(const gr_sleep* s, int k) {
  return (!s->can || s->can[k]) && s->mass[k] > 0.0f;
}

/* the speed beyond which a sleeper wakes, and an awake grain wakes the sleepers it touches:
 * wake radii a second beyond what one substep of the grain's own forces gives (a resting grain's
 * velocity holds up to that much of its fall) */
GR_INLINE float gr_sleep_wake_speed(const gr_sleep_params* sp, const gr_sleep* s, int k) {
  GR_ROW_EXACT
  const gr_float3 F = gr_sleep_force(s, k);
  return sp->wake * s->radius[k] + gr_sleep_length(F.x, F.y, F.z) / s->mass[k] * sp->dt;
}

/* Before the substep: whether grain k, at its start P (world), sleeps through it. One whose
 * stay has reached sleep_time sleeps, unless its force / mass changed since it fell asleep (by
 * more than 1% of it, or 1e-3 m/s^2: a gravity that tilts, a wind that starts) or a move from
 * outside (another node's) took it beyond its stay: then its stay begins again, here. */
GR_INLINE int gr_sleep_begin(const gr_sleep_params* sp, const gr_sleep* s, int k, gr_float3 P) {
  GR_ROW_EXACT
  gr_float3 F, a0, A;
  float m, da, dp;
  if (!gr_sleep_can(s, k) || !(s->time[k] >= sp->sleep_time)) return 0;
  F = gr_sleep_force(s, k);
  m = s->mass[k];
  a0 = gr_load3(s->accel, k);
  A = gr_load3(s->anchor, k);
  da = gr_sleep_length(F.x / m - a0.x, F.y / m - a0.y, F.z / m - a0.z);
  dp = gr_sleep_length(P.x - A.x, P.y - A.y, P.z - A.z);
  if (da > 0.01f * gr_sleep_length(a0.x, a0.y, a0.z) + 1e-3f || dp > sp->stay * s->radius[k]) {
    s->time[k] = 0.0f;
    gr_store3(s->anchor, k, P);
    return 0;
  }
  return 1;
}

/* After the substep, grain k at its end (P, v: world, written back here): a sleeper the substep
 * moved faster than its wake speed (a collider pushed it) wakes there; the others go back to
 * where they slept, still. An awake grain with a mass is `fast` when its start or end speed
 * passes its wake speed. Returns whether it put a sleeper back somewhere else than the substep
 * left it. */
GR_INLINE int gr_sleep_settle(const gr_sleep_params* sp, const gr_sleep* s, int k,
                              GR_GLOBAL float* P, GR_GLOBAL float* v) {
  GR_ROW_EXACT
  const gr_float3 p = gr_load3(P, k);
  s->woken[k] = 0;
  s->fast[k] = 0;
  if (s->asleep[k]) {
    const gr_float3 b = gr_load3(s->start, k);
    if (gr_sleep_length(p.x - b.x, p.y - b.y, p.z - b.z) > gr_sleep_wake_speed(sp, s, k) * sp->dt) {
      s->woken[k] = 1;
      return 0;
    }
    gr_store3(P, k, b);
    gr_store3(v, k, gr_make3(0.0f, 0.0f, 0.0f));
    return gr_as_uint(p.x) != gr_as_uint(b.x) || gr_as_uint(p.y) != gr_as_uint(b.y) ||
           gr_as_uint(p.z) != gr_as_uint(b.z);
  }
  if (s->mass[k] > 0.0f) {
    const gr_float3 a = gr_load3(s->start_v, k), e = gr_load3(v, k);
    const float speed = gr_max(gr_sleep_length(a.x, a.y, a.z), gr_sleep_length(e.x, e.y, e.z));
    s->fast[k] = speed > gr_sleep_wake_speed(sp, s, k);
  }
  return 0;
}

/* Whether collider c, which moved over the substep, reaches grain k at its end P (world, after
 * gr_sleep_settle): within 1.05 r_k plus the way its material there went in the substep. A
 * sleeper it reaches wakes, at its start or end pose alike (a floor that drops away leaves
 * none hanging). */
GR_INLINE int gr_sleep_collider_near(const gr_sleep_params* sp, const gr_sleep* s, int k,
                                     const gr_collider* c, const GR_GLOBAL float* P GR_MESH_PARAM) {
  GR_ROW_EXACT
  float x[3], vc[3];
  float reach;
  x[0] = P[3 * k], x[1] = P[3 * k + 1], x[2] = P[3 * k + 2];
  gr_collider_velocity(c, x, vc);
  reach = 1.05f * s->radius[k] + gr_sleep_length(vc[0], vc[1], vc[2]) * sp->dt;
  return gr_collider_distance_within(c, x, 0, 2.0f * reach GR_MESH_ARG(mesh)) < reach;
}

/* A sleeper not yet woken wakes when a contact it slept on is gone (`kept`: the grains within
 * GR_SLEEP_KEPT x the summed radii, fewer than the `contacts` within GR_SLEEP_NEAR when it fell
 * asleep: a grain under it was killed, or rolled away) or a fast grain lies within
 * GR_SLEEP_NEAR x the summed radii (`fast_near`). */
GR_INLINE void gr_sleep_rows_wake(const gr_sleep* s, int k, int kept, int fast_near) {
  if (s->asleep[k] && !s->woken[k] && (kept < s->contacts[k] || fast_near)) s->woken[k] = 1;
}

/* Last, grain k at its end P (world, after gr_sleep_settle) with velocity v: a sleeper that
 * sleeps on keeps its stay; a woken one, one that may not sleep, or one beyond its stay begins
 * its stay again here; the others count the substep and fall asleep when their stay reaches
 * sleep_time, with v = 0 and their force / mass noted. Returns 1 for a grain falling asleep
 * now: the caller notes its contacts, the grains within GR_SLEEP_NEAR x the summed radii. */
GR_INLINE int gr_sleep_stay(const gr_sleep_params* sp, const gr_sleep* s, int k,
                            const GR_GLOBAL float* P, GR_GLOBAL float* v) {
  GR_ROW_EXACT
  const gr_float3 p = gr_load3(P, k), A = gr_load3(s->anchor, k);
  gr_float3 F;
  float m;
  if (s->asleep[k] && !s->woken[k]) return 0;
  if (s->woken[k] || !gr_sleep_can(s, k) ||
      gr_sleep_length(p.x - A.x, p.y - A.y, p.z - A.z) > sp->stay * s->radius[k]) {
    gr_store3(s->anchor, k, p);
    s->time[k] = 0.0f;
    return 0;
  }
  s->time[k] += sp->dt;
  if (!(s->time[k] >= sp->sleep_time)) return 0;
  gr_store3(v, k, gr_make3(0.0f, 0.0f, 0.0f));
  F = gr_sleep_force(s, k);
  m = s->mass[k];
  gr_store3(s->accel, k, gr_make3(F.x / m, F.y / m, F.z / m));
  return 1;
}

#endif /* GRAINS_KERNELS_SLEEP_H */
