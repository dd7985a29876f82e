/* The analytic collider shapes' signed distances, a collider's rigid pose and the velocity of its
 * material: one definition for the CPU (engine/collider.cpp) and an OpenCL device (the grains
 * node's collider planes, nodes/grains/opencl/grains.cl, which compiles this same file).
 *
 * A pose places the local shape in the world with uniform scale, world = t + s R local (R
 * row-major). The local shapes: plane y = 0, solid below (normal +y); box centred, full extents
 * `size`; sphere of `radius`; torus in the xz plane, `radius` (ring) and `tube`; capsule along
 * y, `height` between the hemisphere centres and `radius`. A mesh's distance is not
 * gr_shape_distance's (which gives it 1e30) but engine/mesh_query.h's (gr_local_distance, below).
 *
 * Both sides take the same float operations in the same order, the device's division and
 * square root correctly rounded (-cl-fp32-correctly-rounded-divide-sqrt), and neither fuses a
 * multiply and an add: each function opens with GR_SHAPE_EXACT (the device's FP_CONTRACT off),
 * and the host compiles their callers without contraction (engine/collider.cpp and
 * nodes/grains/planes.cpp, -ffp-contract=off in CMakeLists.txt). A device finds the CPU's
 * floats, bit for bit.
 *
 * Written in the subset common to C, C++ and OpenCL C; the arrays are private (a kernel copies
 * a collider out of global memory first). */
#ifndef GRAINS_ENGINE_COLLIDER_SHAPE_H
#define GRAINS_ENGINE_COLLIDER_SHAPE_H

#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)
#define GR_SHAPE_SQRT sqrt
#define GR_SHAPE_FABS fabs
#define GR_SHAPE_EXACT _Pragma("OPENCL FP_CONTRACT OFF")
#else
#include <math.h>
#define GR_SHAPE_SQRT sqrtf
#define GR_SHAPE_FABS fabsf
#define GR_SHAPE_EXACT
#endif

/* the kinds, in engine::ShapeKind's order */
#define GR_SHAPE_PLANE 0
#define GR_SHAPE_BOX 1
#define GR_SHAPE_SPHERE 2
#define GR_SHAPE_TORUS 3
#define GR_SHAPE_CAPSULE 4
#define GR_SHAPE_MESH 5

typedef struct {
  int kind;
  float size[3];
  float radius, tube, height;
} gr_shape;

typedef struct {
  float R[9]; /* row-major rotation */
  float t[3];
  float s;
} gr_pose;

/* a collider over one substep: its shape, its pose at the substep's end and at its start, and
 * the substep's length (s; 0: no velocity). The same 136 bytes on both sides. */
typedef struct {
  gr_shape shape;
  gr_pose pose, prev;
  float dt;
} gr_collider;

/* the larger and smaller of a and b as std::max and std::min take them (a NaN as they do) */
static inline float gr_shape_max(float a, float b) {
  return a < b ? b : a;
}
static inline float gr_shape_min(float a, float b) {
  return b < a ? b : a;
}

/* d / l into n, or the axis `fallback` (0, 1, 2) when l is not positive */
static inline void gr_shape_unit(const float* d, float l, int fallback, float* n) {
  int a;
  for (a = 0; a < 3; ++a) n[a] = l > 0.0f ? d[a] / l : (a == fallback ? 1.0f : 0.0f);
}

static inline float gr_shape_length(const float* v) {
  GR_SHAPE_EXACT
  return GR_SHAPE_SQRT(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

static inline void gr_pose_rotate(const gr_pose* q, const float* d, float* out) {
  GR_SHAPE_EXACT
  out[0] = q->R[0] * d[0] + q->R[1] * d[1] + q->R[2] * d[2];
  out[1] = q->R[3] * d[0] + q->R[4] * d[1] + q->R[5] * d[2];
  out[2] = q->R[6] * d[0] + q->R[7] * d[1] + q->R[8] * d[2];
}

static inline void gr_pose_unrotate(const gr_pose* q, const float* d, float* out) {
  GR_SHAPE_EXACT
  out[0] = q->R[0] * d[0] + q->R[3] * d[1] + q->R[6] * d[2];
  out[1] = q->R[1] * d[0] + q->R[4] * d[1] + q->R[7] * d[2];
  out[2] = q->R[2] * d[0] + q->R[5] * d[1] + q->R[8] * d[2];
}

/* world = t + (R body) s, body a point in the shape's own frame (`local` is an OpenCL C keyword) */
static inline void gr_pose_apply(const gr_pose* q, const float* body, float* out) {
  GR_SHAPE_EXACT
  float r[3];
  int a;
  gr_pose_rotate(q, body, r);
  for (a = 0; a < 3; ++a) out[a] = q->t[a] + r[a] * q->s;
}

/* body = R^T (world - t) / s */
static inline void gr_pose_inverse(const gr_pose* q, const float* world, float* out) {
  GR_SHAPE_EXACT
  float d[3], r[3];
  int a;
  for (a = 0; a < 3; ++a) d[a] = world[a] - q->t[a];
  gr_pose_unrotate(q, d, r);
  for (a = 0; a < 3; ++a) out[a] = r[a] / q->s;
}

/* the signed distance of the local point p from the shape (negative inside), and its outward
 * normal into n (3 floats; null: none) */
static inline float gr_shape_distance(const gr_shape* sh, const float* p, float* n) {
  GR_SHAPE_EXACT
  float l, d[3];
  int a;
  switch (sh->kind) {
    case GR_SHAPE_PLANE:
      if (n) n[0] = 0.0f, n[1] = 1.0f, n[2] = 0.0f;
      return p[1];
    case GR_SHAPE_SPHERE:
      l = gr_shape_length(p);
      if (n) gr_shape_unit(p, l, 1, n);
      return l - sh->radius;
    case GR_SHAPE_BOX: {
      float q[3], qo[3], outside, inside;
      for (a = 0; a < 3; ++a) {
        q[a] = GR_SHAPE_FABS(p[a]) - sh->size[a] * 0.5f;
        qo[a] = gr_shape_max(q[a], 0.0f);
      }
      outside = gr_shape_length(qo);
      inside = gr_shape_min(gr_shape_max(q[0], gr_shape_max(q[1], q[2])), 0.0f);
      if (n) {
        if (outside > 0.0f) {
          for (a = 0; a < 3; ++a) n[a] = qo[a] / outside;
        } else { /* inside: out through the nearest face */
          const int f = (q[0] >= q[1] && q[0] >= q[2]) ? 0 : (q[1] >= q[2] ? 1 : 2);
          for (a = 0; a < 3; ++a) n[a] = a == f ? 1.0f : 0.0f;
        }
        for (a = 0; a < 3; ++a) n[a] = p[a] < 0.0f ? -n[a] : n[a];
      }
      return outside + inside;
    }
    case GR_SHAPE_TORUS: {
      const float lxz = GR_SHAPE_SQRT(p[0] * p[0] + p[2] * p[2]);
      if (lxz > 0.0f) {
        d[0] = p[0] - p[0] / lxz * sh->radius;
        d[1] = p[1] - 0.0f;
        d[2] = p[2] - p[2] / lxz * sh->radius;
      } else {
        d[0] = p[0] - sh->radius;
        d[1] = p[1] - 0.0f;
        d[2] = p[2] - 0.0f;
      }
      l = gr_shape_length(d);
      if (n) gr_shape_unit(d, l, 1, n);
      return l - sh->tube;
    }
    case GR_SHAPE_CAPSULE: {
      const float hy = sh->height * 0.5f;
      const float cy = p[1] < -hy ? -hy : (hy < p[1] ? hy : p[1]); /* std::clamp */
      d[0] = p[0] - 0.0f;
      d[1] = p[1] - cy;
      d[2] = p[2] - 0.0f;
      l = gr_shape_length(d);
      if (n) gr_shape_unit(d, l, 0, n);
      return l - sh->radius;
    }
    default:
      break;
  }
  if (n) n[0] = 0.0f, n[1] = 1.0f, n[2] = 0.0f;
  return 1e30f;
}

/* the world signed distance of x from the shape placed by q, and the outward normal into n
 * (null: none) */
static inline float gr_placed_distance(const gr_shape* sh, const gr_pose* q, const float* x,
                                       float* n) {
  GR_SHAPE_EXACT
  float body[3], nl[3];
  float d;
  gr_pose_inverse(q, x, body);
  d = gr_shape_distance(sh, body, n ? nl : 0) * q->s;
  if (n) gr_pose_rotate(q, nl, n);
  return d;
}

/* the world signed distance of x from the collider at its end pose, and the outward normal into
 * n (null: none) */
static inline float gr_collider_distance(const gr_collider* c, const float* x, float* n) {
  return gr_placed_distance(&c->shape, &c->pose, x, n);
}

/* the velocity of the collider's material at world point x over the substep (m/s): where the
 * collider carried it from, (x - prev(pose^-1 x)) / dt; none when dt <= 0 */
static inline void gr_collider_velocity(const gr_collider* c, const float* x, float* v) {
  GR_SHAPE_EXACT
  float body[3], back[3];
  int a;
  if (c->dt <= 0.0f) {
    v[0] = v[1] = v[2] = 0.0f;
    return;
  }
  gr_pose_inverse(&c->pose, x, body);
  gr_pose_apply(&c->prev, body, back);
  for (a = 0; a < 3; ++a) v[a] = (x[a] - back[a]) / c->dt;
}

/* A mesh's queries are engine/mesh_query.h's. The functions below take each collider's mesh
 * (null for an analytic shape) as their last argument, GR_MESH_PARAM: on the host a MeshShape
 * (engine/mesh_shape.h), through the hooks engine/collider.cpp defines; on an OpenCL device the
 * mesh's arrays there (gr_mesh, private, pointing into global memory), through the hooks the
 * program defines (nodes/grains/opencl/grains.cl: the queries where the device has double
 * precision; without it the host keeps every mesh's queries). */
#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)
#include "mesh_query.h"
#define GR_MESH_PARAM , const gr_mesh* mesh
#define GR_MESH_TYPE const gr_mesh*
#else
#define GR_MESH_PARAM , const void* mesh
#define GR_MESH_TYPE const void*
#endif
#define GR_MESH_ARG(m) , m
/* A loop over the colliders takes their meshes as GR_MESHES_PARAM and collider c's as
 * GR_MESH_OF_COLLIDER(name, c), which declares `name` (null: an analytic shape): on the host
 * meshes[c], MeshShapes (meshes null: none); on a device collider c's in the set of words
 * `meshes` (engine/mesh_query.h, gr_mesh_of; null: none). */
#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)
#define GR_MESHES_PARAM , __global const int* meshes
#define GR_MESH_OF_COLLIDER(name, c) \
  gr_mesh name##_arrays;             \
  const gr_mesh* name = gr_mesh_of(meshes, c, &name##_arrays)
#else
#define GR_MESHES_PARAM , const void* const* meshes
#define GR_MESH_OF_COLLIDER(name, c) const void* name = meshes ? meshes[c] : 0
#endif
/* the distance from local p (normal n or null, exact below `within`: MeshShape::distance), the
 * first crossing of local a to b (normal n: MeshShape::crossing) and whether the mesh is a shell
 * (not closed) */
float gr_mesh_distance(GR_MESH_TYPE mesh, const float* p, float* n, float within);
float gr_mesh_crossing(GR_MESH_TYPE mesh, const float* a, const float* b, float* n);
int gr_mesh_shell(GR_MESH_TYPE mesh);

/* the local shape's signed distance at p, exact below `within` (a mesh may give anything from
 * `within` up to its distance beyond; the analytic shapes are exact everywhere) */
static inline float gr_local_distance(const gr_shape* sh, const float* p, float* n,
                                      float within GR_MESH_PARAM) {
  if (sh->kind == GR_SHAPE_MESH && mesh) return gr_mesh_distance(mesh, p, n, within);
  return gr_shape_distance(sh, p, n);
}

/* gr_collider_distance exact below `within` (world units), which lets a mesh skip its far
 * triangles */
static inline float gr_collider_distance_within(const gr_collider* c, const float* x, float* n,
                                                float within GR_MESH_PARAM) {
  GR_SHAPE_EXACT
  float body[3], nl[3];
  float d;
  gr_pose_inverse(&c->pose, x, body);
  d = gr_local_distance(&c->shape, body, n ? nl : 0, within / c->pose.s GR_MESH_ARG(mesh)) *
      c->pose.s;
  if (n) gr_pose_rotate(&c->pose, nl, n);
  return d;
}

/* whether the collider did not move over the substep (the same pose, bit for bit) */
static inline int gr_collider_still(const gr_collider* c) {
  int k;
  for (k = 0; k < 9; ++k)
    if (c->pose.R[k] != c->prev.R[k]) return 0;
  for (k = 0; k < 3; ++k)
    if (c->pose.t[k] != c->prev.t[k]) return 0;
  return c->pose.s == c->prev.s;
}

/* Continuous test: a sphere of `radius` moving from a (start of the substep, world) to b (its
 * end), relative to the collider's own motion: the start against the start pose, the end against
 * the end pose, then a sphere trace of the segment against the still local shape. Returns the
 * fraction in [0, 1] of the first time its distance reaches `radius` (0: it starts there), or a
 * value > 1 when it never does. */
static inline float gr_collider_sweep(const gr_collider* c, const float* a, const float* b,
                                      float radius GR_MESH_PARAM) {
  GR_SHAPE_EXACT
  float la[3], lb[3], d[3], dir[3], x[3];
  float r, len, s, dist;
  int k, it;
  gr_pose_inverse(&c->prev, a, la);
  gr_pose_inverse(&c->pose, b, lb);
  r = radius / c->pose.s;
  for (k = 0; k < 3; ++k) d[k] = lb[k] - la[k];
  len = gr_shape_length(d);
  /* a step needs the distance only up to what is left of the segment (past it the trace ends) */
  if (gr_local_distance(&c->shape, la, 0, 2 * r + len GR_MESH_ARG(mesh)) <= r) return 0.0f;
  if (len <= 0.0f) return 2.0f;
  for (k = 0; k < 3; ++k) dir[k] = d[k] / len;
  s = 0.0f;
  for (it = 0; it < 256; ++it) {
    for (k = 0; k < 3; ++k) x[k] = la[k] + dir[k] * s;
    dist = gr_local_distance(&c->shape, x, 0, 2 * r + (len - s) GR_MESH_ARG(mesh)) - r;
    if (dist <= 1e-6f * (1.0f + len)) return s / len;
    s += dist;
    if (s > len) break;
  }
  /* the end point may still be inside if tracing stopped short of it */
  return gr_local_distance(&c->shape, lb, 0, 2 * r GR_MESH_ARG(mesh)) <= r ? 1.0f : 2.0f;
}

/* For a shell (an open mesh, which has no inside): where a point moving from a (start of the
 * substep, world) to b (its end) passed through it, relative to its motion. Returns the fraction
 * along the path (> 1 when it did not, and always for an analytic shape), the crossing point
 * carried to the end pose into `at` and the shell's normal there, turned toward the side the
 * point came from, into `side`. */
static inline float gr_collider_shell_crossing(const gr_collider* c, const float* a, const float* b,
                                               float* at, float* side GR_MESH_PARAM) {
  GR_SHAPE_EXACT
  float la[3], lb[3], n[3], x[3];
  float t, along;
  int k;
  if (!(c->shape.kind == GR_SHAPE_MESH && mesh && gr_mesh_shell(mesh))) return 2.0f;
  gr_pose_inverse(&c->prev, a, la);
  gr_pose_inverse(&c->pose, b, lb);
  t = gr_mesh_crossing(mesh, la, lb, n);
  if (!(t <= 1.0f)) return 2.0f;
  for (k = 0; k < 3; ++k) x[k] = la[k] + (lb[k] - la[k]) * t;
  gr_pose_apply(&c->pose, x, at);
  /* the point came from the side its path leaves behind */
  along = (lb[0] - la[0]) * n[0] + (lb[1] - la[1]) * n[1] + (lb[2] - la[2]) * n[2];
  if (along > 0.0f)
    for (k = 0; k < 3; ++k) n[k] = -n[k];
  gr_pose_rotate(&c->pose, n, side);
  return t;
}

#endif
