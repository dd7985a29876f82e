/* The analytic collider shapes' signed distances, a collider's rigid pose and the velocity of its
 * material: one definition for the CPU (engine/collider.cpp) and an OpenCL device (the grains
 * node's collider planes, nodes/grains/opencl/grains.cl, which compiles this same file).
 *
 * A pose places the local shape in the world with uniform scale, world = t + s R local (R
 * row-major). The local shapes: plane y = 0, solid below (normal +y); box centred, full extents
 * `size`; sphere of `radius`; torus in the xz plane, `radius` (ring) and `tube`; capsule along
 * y, `height` between the hemisphere centres and `radius`. A mesh has no distance here (the CPU
 * has its own, engine/mesh_shape.h): gr_shape_distance gives it 1e30.
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

#endif
