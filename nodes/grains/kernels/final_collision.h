/* The final collision test (help page "Final Collision Test"; DESIGN §4 step 4): after the
 * velocity update each grain, moving from a (its start, world) to b (its end, world) with
 * velocity v and radius r, is tested against each collider in turn (gr_final_collision, for the
 * colliders in order; a fixed grain is not tested):
 *  - an end point closer than r to the surface is pushed out to distance r along the normal
 *    (unless it came through the collider, below);
 *  - otherwise a path that came within r/2 of the surface somewhere between a and b (the sphere
 *    trace gr_collider_sweep, relative to the collider's motion) tunnelled through a thin or
 *    moving collider: the grain is put where the trace first reached distance r, carried by the
 *    collider to its end pose, and pushed out to r. The r/2 test keeps grains sliding along a
 *    surface at distance ~r from counting as hits;
 *  - a path through a shell (an open mesh, which has no inside) is put back at r on the side it
 *    came from, whatever its distances say (first of the three).
 * Every way the velocity component into the collider is removed. A tunnelling grain's contact
 * was never seen by the iterations, so its collider friction was not applied either: the pass
 * applies it (gr_swept_friction) to the hit. An end point within r was in the iterations'
 * contact planes, which already had its friction.
 *
 * The CPU runs it in GrainsSolver::write_back (through final_collision.cpp, compiled without
 * contraction), an OpenCL device in gr_k_final_collision. The distances, sweeps and poses are
 * engine/collider_shape.h's (a mesh's engine/mesh_query.h's), and like them these functions
 * fuse no multiply and add (GR_SHAPE_EXACT): a device moves a grain where the CPU does, bit for
 * bit (its velocity within the friction's rounding, gr_friction being fused there). */
#ifndef GRAINS_KERNELS_FINAL_COLLISION_H
#define GRAINS_KERNELS_FINAL_COLLISION_H
#include "contact.h"
/* the device's program holds engine/collider_shape.h beside the kernel headers */
#if defined(GR_OPENCL)
#include "collider_shape.h"
#else
#include "engine/collider_shape.h"
#endif

/* Removes the velocity component of v into a collider of normal n, relative to the collider's
 * own velocity vc; returns the normal speed removed (>= 0). */
GR_INLINE float gr_remove_inward(float* v, const float* n, const float* vc) {
  GR_SHAPE_EXACT
  const float vn = (v[0] - vc[0]) * n[0] + (v[1] - vc[1]) * n[1] + (v[2] - vc[2]) * n[2];
  int k;
  if (!(vn < 0.0f)) return 0.0f;
  for (k = 0; k < 3; ++k) v[k] = v[k] - n[k] * vn;
  return -vn;
}

/* Collider friction at velocity level: the kernels' law (eqs. 23-25, gr_friction) with slip and
 * overlap per substep both divided by dt, so that the normal speed the pass removed bounds the
 * tangential speed relative to the collider: |v_t| < static_threshold x mu x removed stops it,
 * else it loses min(1, scale_kinetic x mu x removed / |v_t|) of it. mu = friction_with_colliders
 * x the grain's friction. */
GR_INLINE void gr_swept_friction(float* v, const float* n, const float* vc, float removed,
                                 float mu, float static_threshold, float scale_kinetic) {
  GR_SHAPE_EXACT
  gr_float3 dv;
  if (!(mu > 0.0f) || !(removed > 0.0f)) return;
  dv = gr_friction(gr_make3(v[0] - vc[0], v[1] - vc[1], v[2] - vc[2]), gr_make3(n[0], n[1], n[2]),
                   mu * removed, static_threshold, scale_kinetic);
  v[0] = v[0] + dv.x;
  v[1] = v[1] + dv.y;
  v[2] = v[2] + dv.z;
}

/* b + n x (r - e): a point at distance e along normal n pushed out to r */
GR_INLINE void gr_push_out(float* b, const float* n, float r, float e) {
  GR_SHAPE_EXACT
  int k;
  for (k = 0; k < 3; ++k) b[k] = b[k] + n[k] * (r - e);
}

/* The pass of one grain (a to b, velocity v, radius r, friction mu) against collider c: returns
 * 1 when it acted, with the normal it pushed along in hit_n, else 0. */
GR_INLINE int gr_final_collision(const gr_collider* c, const float* a, float* b, float* v,
                                 float r, float mu, float static_threshold, float scale_kinetic,
                                 float* hit_n GR_MESH_PARAM) {
  GR_SHAPE_EXACT
  float ab[3], n[3], at[3], side[3], vc[3], la[3], lb[3], x[3];
  float travel, e, t_half, t, eh;
  int near, k;
  for (k = 0; k < 3; ++k) ab[k] = b[k] - a[k];
  travel = gr_shape_length(ab);
  /* exact up to past both tests below (a mesh skips its triangles beyond) */
  e = gr_collider_distance_within(c, b, n, 1.505f * r + travel GR_MESH_ARG(mesh));
  /* An end point within r is pushed out, unless the grain moved along that normal and its path
   * crossed the collider: then it is on the far side of a thin one (the iterations pushed it out
   * the back) and is handled as tunnelled below. Moving along the normal, a path that does not
   * cross never comes within r/2 of the surface unless it started there. */
  near = e < r;
  /* A still collider's signed distance changes by at most the distance moved, so a path that
   * ends more than r/2 + |b - a| away never came within r/2 of it: the sweep would find no hit
   * (checked with a 1% margin on r/2, far above the trace's tolerance and float error). */
  if (!near && gr_collider_still(c) && e > 0.505f * r + travel) return 0;
  /* A shell has no inside, so its distance cannot tell a grain pressed through it by its
   * neighbours (or one that started within r/2, where the sweep below reports nothing) from one
   * on its own side: the path's crossing can. Such a grain is put back at r on the side it came
   * from; as with a tunnelled grain, the iterations never held it there, so the pass applies
   * the friction. */
  if (gr_collider_shell_crossing(c, a, b, at, side GR_MESH_ARG(mesh)) <= 1.0f) {
    for (k = 0; k < 3; ++k) b[k] = at[k] + side[k] * r;
    e = gr_collider_distance_within(c, b, n, INFINITY GR_MESH_ARG(mesh));
    if (e < r) gr_push_out(b, n, r, e);
    gr_collider_velocity(c, b, vc);
    gr_swept_friction(v, side, vc, gr_remove_inward(v, side, vc), mu, static_threshold,
                      scale_kinetic);
    for (k = 0; k < 3; ++k) hit_n[k] = side[k];
    return 1;
  }
  t_half = 2.0f; /* > 1: no hit */
  if (!near || ab[0] * n[0] + ab[1] * n[1] + ab[2] * n[2] > 0.0f)
    t_half = gr_collider_sweep(c, a, b, 0.5f * r GR_MESH_ARG(mesh));
  if (!(t_half > 0.0f && t_half <= 1.0f)) { /* 0: started deep (and left), > 1: no hit */
    if (!near) return 0;
    gr_push_out(b, n, r, e);
    gr_collider_velocity(c, b, vc);
    gr_remove_inward(v, n, vc);
    for (k = 0; k < 3; ++k) hit_n[k] = n[k];
    return 1;
  }
  t = gr_shape_min(gr_collider_sweep(c, a, b, r GR_MESH_ARG(mesh)), t_half);
  /* where the trace reached r, carried by the collider to its end pose */
  gr_pose_inverse(&c->prev, a, la);
  gr_pose_inverse(&c->pose, b, lb);
  for (k = 0; k < 3; ++k) x[k] = la[k] + (lb[k] - la[k]) * t;
  gr_pose_apply(&c->pose, x, b);
  eh = gr_collider_distance_within(c, b, n, INFINITY GR_MESH_ARG(mesh));
  if (eh < r) gr_push_out(b, n, r, eh);
  gr_collider_velocity(c, b, vc);
  gr_swept_friction(v, n, vc, gr_remove_inward(v, n, vc), mu, static_threshold, scale_kinetic);
  for (k = 0; k < 3; ++k) hit_n[k] = n[k];
  return 1;
}

/* The pass of one grain against `count` colliders in order, each with its mesh
 * (GR_MESH_OF_COLLIDER, engine/collider_shape.h). Returns the last collider that
 * acted, with its normal in hit_n, or -1 when none did. */
GR_INLINE int gr_final_collisions(const GR_GLOBAL gr_collider* colliders, int count, const float* a,
                                  float* b, float* v, float r, float mu, float static_threshold,
                                  float scale_kinetic, float* hit_n GR_MESHES_PARAM) {
  float n[3];
  int c, k, hit = -1;
  for (c = 0; c < count; ++c) {
#if defined(GR_OPENCL)
    const gr_collider copy = colliders[c]; /* the shared functions read private memory */
    const gr_collider* col = &copy;
#else
    const gr_collider* col = &colliders[c];
#endif
    GR_MESH_OF_COLLIDER(mesh, c);
    if (gr_final_collision(col, a, b, v, r, mu, static_threshold, scale_kinetic,
                           n GR_MESH_ARG(mesh))) {
      hit = c;
      for (k = 0; k < 3; ++k) hit_n[k] = n[k];
    }
  }
  return hit;
}

#endif /* GRAINS_KERNELS_FINAL_COLLISION_H */
