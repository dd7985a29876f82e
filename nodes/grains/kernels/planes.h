/* A grain's collider planes (GrainsSolver::find_planes on the CPU, nodes/grains/planes.cpp;
 * gr_k_plane_count and gr_k_plane_fill on an OpenCL device): the colliders whose surface lies
 * within the grain's range of its predicted centre, at most GR_MAX_PLANES of them, nearest first
 * (ties by collider order). The range is query_scale x its radius widened by the substep's
 * motion |p - P|, so that a grain the iterations push back toward where it came from still
 * finds the surface it moved away from. A fixed grain (inverse mass 0) has none: nothing moves
 * it, a collider through it neither. Each entry is the surface point x - n d (the substep's
 * coordinates), the outward normal n and the collider's velocity there (9 floats), and the
 * collider's index. Colliders live in the world, the grains in the substep's coordinates:
 * world = those + origin.
 *
 * The distances and velocities are engine/collider_shape.h's, and like them these functions
 * fuse no multiply and add (GR_SHAPE_EXACT; the CPU's caller is compiled without contraction):
 * the device's planes are the CPU's, bit for bit. */
#ifndef GRAINS_KERNELS_PLANES_H
#define GRAINS_KERNELS_PLANES_H
#include "collider.h"
/* the device's program holds engine/collider_shape.h beside the kernel headers */
#if defined(GR_OPENCL)
#include "collider_shape.h"
#else
#include "engine/collider_shape.h"
#endif

/* the range within which a grain of radius `radius` at p (from P) looks for collider surfaces */
GR_INLINE float gr_plane_range(float query_scale, float radius, const float* p, const float* P) {
  GR_SHAPE_EXACT
  const float d[3] = {p[0] - P[0], p[1] - P[1], p[2] - P[2]};
  return query_scale * radius + gr_sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
}

/* the world point of the substep's point p */
GR_INLINE void gr_plane_world(const float* p, const float* origin, float* x) {
  GR_SHAPE_EXACT
  x[0] = p[0] + origin[0];
  x[1] = p[1] + origin[1];
  x[2] = p[2] + origin[2];
}

/* collider c at distance d (normal nc) into the nearest-first list of `count` (dist, nrm: 3 a
 * plane, idx), which keeps the GR_MAX_PLANES nearest of those nearer than `range`; returns the
 * list's new count. Call it for the colliders in order. */
GR_INLINE int gr_plane_insert(float d, const float* nc, int c, float range, float* dist,
                              float* nrm, int* idx, int count) {
  int at = count < GR_MAX_PLANES ? count : GR_MAX_PLANES;
  int last, k;
  if (!(d < range)) return count;
  while (at > 0 && d < dist[at - 1]) --at;
  if (at >= GR_MAX_PLANES) return count;
  last = count < GR_MAX_PLANES - 1 ? count : GR_MAX_PLANES - 1;
  for (k = last; k > at; --k) {
    dist[k] = dist[k - 1];
    nrm[3 * k] = nrm[3 * (k - 1)];
    nrm[3 * k + 1] = nrm[3 * (k - 1) + 1];
    nrm[3 * k + 2] = nrm[3 * (k - 1) + 2];
    idx[k] = idx[k - 1];
  }
  dist[at] = d;
  nrm[3 * at] = nc[0];
  nrm[3 * at + 1] = nc[1];
  nrm[3 * at + 2] = nc[2];
  idx[at] = c;
  return count + 1 < GR_MAX_PLANES ? count + 1 : GR_MAX_PLANES;
}

/* a plane's surface point x - n d in the substep's coordinates (p: the grain's predicted
 * centre there) and the same point in the world */
GR_INLINE void gr_plane_surface(const float* p, const float* n, float d, const float* origin,
                                float* xs, float* world) {
  GR_SHAPE_EXACT
  int a;
  for (a = 0; a < 3; ++a) xs[a] = p[a] - n[a] * d;
  gr_plane_world(xs, origin, world);
}

/* grain i's planes among `count` colliders (their world distances within its range, a mesh's
 * exact there: gr_collider_distance_within; each collider's mesh GR_MESH_OF_COLLIDER's), into
 * dist, nrm and idx; returns how many */
GR_INLINE int gr_plane_nearest(GR_GLOBAL const gr_collider* colliders, int count,
                               const float* origin, float query_scale, float radius, float inv_mass,
                               const float* p, const float* P, float* dist, float* nrm,
                               int* idx GR_MESHES_PARAM) {
  float x[3], range;
  int c, found = 0;
  if (!(inv_mass > 0.0f)) return 0;
  gr_plane_world(p, origin, x);
  range = gr_plane_range(query_scale, radius, p, P);
  for (c = 0; c < count; ++c) {
    const gr_collider col = colliders[c];
    float nc[3];
    GR_MESH_OF_COLLIDER(mesh, c);
    const float d = gr_collider_distance_within(&col, x, nc, range GR_MESH_ARG(mesh));
    found = gr_plane_insert(d, nc, c, range, dist, nrm, idx, found);
  }
  return found;
}

#endif
