/* A triangle mesh collider's queries (engine/mesh_shape.h): the distance from a point to the
 * surface and the first crossing of a segment, walking the bounding-volume hierarchy MeshShape
 * builds. One definition for the CPU (MeshShape::distance and ::crossing, engine/mesh_shape.cpp)
 * and an OpenCL device (the grains node's collider planes, final collision test and sleeping
 * test, nodes/grains/opencl/grains.cl), which reads the same arrays from its own buffers.
 *
 * The triangle tests are in double precision, so a device needs cl_khr_fp64. Both sides take
 * the same operations in the same order and neither fuses a multiply and an add (GR_MESH_EXACT:
 * the device's FP_CONTRACT off; the host compiles engine/mesh_shape.cpp without contraction),
 * and OpenCL rounds double division and square root correctly: a device finds the CPU's
 * distances, normals and crossings, bit for bit.
 *
 * Written in the subset common to C, C++ and OpenCL C. A device's program includes this file
 * twice: for the types (before double precision is enabled) and, where the device has it, with
 * GR_MESH_QUERIES defined, for the queries. */
#ifndef GRAINS_ENGINE_MESH_TYPES_H
#define GRAINS_ENGINE_MESH_TYPES_H

#if defined(__OPENCL_VERSION__) || defined(__OPENCL_C_VERSION__)
#define GR_MESH_GLOBAL __global
#define GR_MESH_EXACT _Pragma("OPENCL FP_CONTRACT OFF")
#define GR_MESH_ISINF(x) isinf(x)
#define GR_MESH_ISFINITE(x) isfinite(x)
#define GR_MESH_DSQRT(x) sqrt(x)
#define GR_MESH_DFABS(x) fabs(x)
#else
#include <math.h>
#define GR_MESH_GLOBAL
#define GR_MESH_EXACT
#define GR_MESH_ISINF(x) __builtin_isinf(x)
#define GR_MESH_ISFINITE(x) __builtin_isfinite(x)
#define GR_MESH_DSQRT(x) sqrt(x)
#define GR_MESH_DFABS(x) fabs(x)
#endif

/* a node of the hierarchy: its box; a leaf holds triangles [first, first + count), an inner
 * node (count 0) has children first and first + 1. 32 bytes on both sides. */
typedef struct {
  float lo[3], hi[3];
  int first, count;
} gr_mesh_node;

/* a built mesh, where its arrays are (host memory, or a device's global memory): the nodes
 * (root first), the triangles' vertex indices (3 a triangle, in the hierarchy's order), the
 * vertices (3 floats each), each triangle's unit normal (3), its edges' pseudonormals (9: edge
 * k joins vertex k and vertex (k + 1) % 3), each vertex's pseudonormal (3), the vertices' box,
 * and whether the mesh is closed (a solid: signed distance; else a shell) */
typedef struct {
  GR_MESH_GLOBAL const gr_mesh_node* nodes;
  GR_MESH_GLOBAL const int* tri;
  GR_MESH_GLOBAL const float* vertices;
  GR_MESH_GLOBAL const float* face_n;
  GR_MESH_GLOBAL const float* edge_n;
  GR_MESH_GLOBAL const float* vertex_n;
  float lo[3], hi[3];
  int closed;
} gr_mesh;

/* A set of meshes stored end to end in one array of 4-byte words (a device's buffer,
 * Iterations::set_meshes): `count` of these first, one a collider, then each mesh's arrays.
 * Word offsets of collider c's nodes, triangles, vertices, face, edge and vertex normals, its
 * box and whether it is closed; nodes < 0: an analytic collider. 52 bytes. */
typedef struct {
  int nodes, tri, vertices, face_n, edge_n, vertex_n, closed;
  float lo[3], hi[3];
} gr_mesh_ref;

/* collider c's mesh in the set `words` (null: no meshes) into *m; returns m, or null for an
 * analytic collider */
static inline const gr_mesh* gr_mesh_of(GR_MESH_GLOBAL const int* words, int c, gr_mesh* m) {
  GR_MESH_GLOBAL const gr_mesh_ref* r;
  int k;
  if (!words) return 0;
  r = (GR_MESH_GLOBAL const gr_mesh_ref*)words + c;
  if (r->nodes < 0) return 0;
  m->nodes = (GR_MESH_GLOBAL const gr_mesh_node*)(words + r->nodes);
  m->tri = words + r->tri;
  m->vertices = (GR_MESH_GLOBAL const float*)(words + r->vertices);
  m->face_n = (GR_MESH_GLOBAL const float*)(words + r->face_n);
  m->edge_n = (GR_MESH_GLOBAL const float*)(words + r->edge_n);
  m->vertex_n = (GR_MESH_GLOBAL const float*)(words + r->vertex_n);
  for (k = 0; k < 3; ++k) m->lo[k] = r->lo[k], m->hi[k] = r->hi[k];
  m->closed = r->closed;
  return m;
}

#endif /* GRAINS_ENGINE_MESH_TYPES_H */

#if (!defined(__OPENCL_VERSION__) && !defined(__OPENCL_C_VERSION__)) || defined(GR_MESH_QUERIES)
#ifndef GRAINS_ENGINE_MESH_QUERY_H
#define GRAINS_ENGINE_MESH_QUERY_H

/* where on a triangle the nearest point lies: its face, a vertex, an edge */
#define GR_MESH_FACE 0
#define GR_MESH_VERTEX0 1
#define GR_MESH_EDGE0 4

static inline double gr_mesh_dot(const double* a, const double* b) {
  GR_MESH_EXACT
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static inline void gr_mesh_cross(const double* a, const double* b, double* out) {
  GR_MESH_EXACT
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

/* out = a + d * s */
static inline void gr_mesh_along(const double* a, const double* d, double s, double* out) {
  GR_MESH_EXACT
  int k;
  for (k = 0; k < 3; ++k) out[k] = a[k] + d[k] * s;
}

static inline void gr_mesh_sub(const double* a, const double* b, double* out) {
  int k;
  for (k = 0; k < 3; ++k) out[k] = a[k] - b[k];
}

static inline void gr_mesh_copy(const double* a, double* out) {
  out[0] = a[0], out[1] = a[1], out[2] = a[2];
}

/* vertex v of the mesh in double precision */
static inline void gr_mesh_vertex(const gr_mesh* m, int v, double* out) {
  out[0] = m->vertices[3 * v], out[1] = m->vertices[3 * v + 1], out[2] = m->vertices[3 * v + 2];
}

/* The point of triangle (a, b, c) nearest to p into out, and its feature (Ericson, Real-Time
 * Collision Detection §5.1.5: the Voronoi regions of the vertices, then the edges, then the
 * face). */
static inline int gr_mesh_closest(const double* p, const double* a, const double* b,
                                  const double* c, double* out) {
  GR_MESH_EXACT
  double ab[3], ac[3], ap[3], bp[3], cp[3], cb[3];
  double d1, d2, d3v, d4, vc, d5, d6, vb, va, inv;
  gr_mesh_sub(b, a, ab), gr_mesh_sub(c, a, ac), gr_mesh_sub(p, a, ap);
  d1 = gr_mesh_dot(ab, ap), d2 = gr_mesh_dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return gr_mesh_copy(a, out), GR_MESH_VERTEX0;
  gr_mesh_sub(p, b, bp);
  d3v = gr_mesh_dot(ab, bp), d4 = gr_mesh_dot(ac, bp);
  if (d3v >= 0 && d4 <= d3v) return gr_mesh_copy(b, out), GR_MESH_VERTEX0 + 1;
  vc = d1 * d4 - d3v * d2;
  if (vc <= 0 && d1 >= 0 && d3v <= 0)
    return gr_mesh_along(a, ab, d1 / (d1 - d3v), out), GR_MESH_EDGE0;
  gr_mesh_sub(p, c, cp);
  d5 = gr_mesh_dot(ab, cp), d6 = gr_mesh_dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return gr_mesh_copy(c, out), GR_MESH_VERTEX0 + 2;
  vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0)
    return gr_mesh_along(a, ac, d2 / (d2 - d6), out), GR_MESH_EDGE0 + 2;
  va = d3v * d6 - d5 * d4;
  if (va <= 0 && d4 - d3v >= 0 && d5 - d6 >= 0) {
    gr_mesh_sub(c, b, cb);
    return gr_mesh_along(b, cb, (d4 - d3v) / ((d4 - d3v) + (d5 - d6)), out), GR_MESH_EDGE0 + 1;
  }
  inv = 1.0 / (va + vb + vc);
  {
    double x[3];
    gr_mesh_along(a, ab, vb * inv, x);
    gr_mesh_along(x, ac, vc * inv, out);
  }
  return GR_MESH_FACE;
}

/* how far q lies outside [lo, hi] along one axis (0 inside) */
static inline double gr_mesh_gap(double q, float lo, float hi) {
  return q < lo ? lo - q : (q > hi ? q - hi : 0.0);
}

/* squared distance from p to the box [lo, hi] (0 inside) */
static inline double gr_mesh_box_distance2(const float* lo, const float* hi, const double* p) {
  GR_MESH_EXACT
  double s = 0, e;
  int k;
  for (k = 0; k < 3; ++k) {
    e = gr_mesh_gap(p[k], lo[k], hi[k]);
    s += e * e;
  }
  return s;
}

/* the same for a node's box, read where the node is (no copy of it: a hot path) */
static inline double gr_mesh_node_distance2(GR_MESH_GLOBAL const gr_mesh_node* nd,
                                            const double* p) {
  GR_MESH_EXACT
  double s = 0, e;
  int k;
  for (k = 0; k < 3; ++k) {
    e = gr_mesh_gap(p[k], nd->lo[k], nd->hi[k]);
    s += e * e;
  }
  return s;
}

/* the parameter where p + t d enters node nd's box within t in [0, 1] (slab test) into *t_in;
 * 0 when it never does there. inv_d: 1 / d per axis (infinite for a zero component). */
static inline int gr_mesh_segment_box(GR_MESH_GLOBAL const gr_mesh_node* nd, const double* p,
                                      const double* inv_d, double* t_in) {
  GR_MESH_EXACT
  double t0 = 0, t1 = 1, ta, tb, sw;
  int k;
  for (k = 0; k < 3; ++k) {
    if (GR_MESH_ISINF(inv_d[k])) {
      if (p[k] < nd->lo[k] || p[k] > nd->hi[k]) return 0;
      continue;
    }
    ta = (nd->lo[k] - p[k]) * inv_d[k], tb = (nd->hi[k] - p[k]) * inv_d[k];
    if (ta > tb) sw = ta, ta = tb, tb = sw;
    t0 = t0 < ta ? ta : t0;
    t1 = tb < t1 ? tb : t1;
    if (t0 > t1) return 0;
  }
  *t_in = t0;
  return 1;
}

/* where p + t d meets triangle (a, b, c), t in [0, 1] (Moeller & Trumbore 1997); a negative
 * value when it does not. Points on an edge count for both triangles that share it. */
static inline double gr_mesh_segment_triangle(const double* p, const double* d, const double* a,
                                              const double* b, const double* c) {
  GR_MESH_EXACT
  double e1[3], e2[3], h[3], s[3], q[3], det, inv, u, v, t;
  gr_mesh_sub(b, a, e1), gr_mesh_sub(c, a, e2);
  gr_mesh_cross(d, e2, h);
  det = gr_mesh_dot(e1, h);
  if (GR_MESH_DFABS(det) < 1e-300) return -1; /* parallel */
  inv = 1.0 / det;
  gr_mesh_sub(p, a, s);
  u = gr_mesh_dot(s, h) * inv;
  if (u < 0 || u > 1) return -1;
  gr_mesh_cross(s, e1, q);
  v = gr_mesh_dot(d, q) * inv;
  if (v < 0 || u + v > 1) return -1;
  t = gr_mesh_dot(e2, q) * inv;
  return t >= 0 && t <= 1 ? t : -1;
}

/* v / |v| into n as floats, +y when v has no length */
static inline void gr_mesh_unit(const double* v, float* n) {
  GR_MESH_EXACT
  const double l = GR_MESH_DSQRT(gr_mesh_dot(v, v));
  int k;
  for (k = 0; k < 3; ++k) n[k] = l > 0 ? (float)(v[k] / l) : (k == 1 ? 1.0f : 0.0f);
}

/* triangle i's corners */
static inline void gr_mesh_triangle(const gr_mesh* m, int i, double* a, double* b, double* c) {
  gr_mesh_vertex(m, m->tri[3 * i], a);
  gr_mesh_vertex(m, m->tri[3 * i + 1], b);
  gr_mesh_vertex(m, m->tri[3 * i + 2], c);
}

/* The first point where the segment a -> b (local) passes through a triangle: its fraction along
 * the segment in (0, 1] and the triangle's unit normal into n, or a value > 1 when it touches no
 * triangle after its start (a start on the surface is on no side). */
static inline float gr_mesh_query_crossing(const gr_mesh* m, const float* af, const float* bf,
                                           float* n) {
  GR_MESH_EXACT
  const double p[3] = {af[0], af[1], af[2]};
  double d[3], inv_d[3], best = INFINITY, t_in, ta[3], tb[3], tc[3], hit;
  int stack[64], top = 0, best_t = -1, i, k;
  for (k = 0; k < 3; ++k) {
    d[k] = (double)bf[k] - p[k];
    inv_d[k] = d[k] != 0 ? 1 / d[k] : INFINITY;
  }
  stack[top++] = 0;
  while (top > 0) {
    GR_MESH_GLOBAL const gr_mesh_node* nd = m->nodes + stack[--top];
    if (!gr_mesh_segment_box(nd, p, inv_d, &t_in) || t_in > best) continue;
    if (nd->count == 0) {
      stack[top++] = nd->first;
      stack[top++] = nd->first + 1;
      continue;
    }
    for (i = nd->first; i < nd->first + nd->count; ++i) {
      gr_mesh_triangle(m, i, ta, tb, tc);
      hit = gr_mesh_segment_triangle(p, d, ta, tb, tc);
      if (hit > 0 && hit < best) best = hit, best_t = i; /* a start on the surface: no side */
    }
  }
  if (best_t < 0) return 2.0f;
  if (n)
    for (k = 0; k < 3; ++k) n[k] = m->face_n[3 * best_t + k];
  return (float)best;
}

/* Distance from local point p to the surface (signed for a closed mesh, negative inside;
 * unsigned for a shell) and the unit normal along which it grows into n (null: none). Exact
 * below `within`; a point at least `within` from the surface (outside) gets some value between
 * `within` and its distance, and the normal +y: the walk skips every box farther than `within`.
 * The sign is the angle-weighted pseudonormal's of the nearest feature (Baerentzen & Aanaes
 * 2005). */
static inline float gr_mesh_query_distance(const gr_mesh* m, const float* pf, float* n,
                                           float within) {
  GR_MESH_EXACT
  const double p[3] = {pf[0], pf[1], pf[2]};
  double cap = within > 0 ? (double)within * (double)within : 0.0;
  double best = cap, best_c[3] = {0, 0, 0}, ta[3], tb[3], tc[3], c[3], away[3], pseudo[3];
  double dist, side, sign, box, da, db, dnear, dfar;
  int stack[64], top, best_t = -1, best_f = GR_MESH_FACE, f, i, k, pass, a, b, a_first;
  /* a closed mesh's far point may be inside it: where nothing lies within `within` and p is in
   * its box, the walk is made again without the cap, for the sign */
  for (pass = 0; pass < 2; ++pass) {
    best = cap, best_t = -1, top = 0;
    /* each visit pops one node and pushes at most two, so the stack holds at most depth + 1
     * nodes; median splits of fewer than 2^31 triangles are under 32 deep */
    stack[top++] = 0;
    while (top > 0) {
      GR_MESH_GLOBAL const gr_mesh_node* nd = m->nodes + stack[--top];
      if (gr_mesh_node_distance2(nd, p) >= best) continue;
      if (nd->count > 0) {
        for (i = nd->first; i < nd->first + nd->count; ++i) {
          double d2;
          gr_mesh_triangle(m, i, ta, tb, tc);
          f = gr_mesh_closest(p, ta, tb, tc, c);
          gr_mesh_sub(p, c, away);
          d2 = gr_mesh_dot(away, away);
          if (d2 < best) best = d2, gr_mesh_copy(c, best_c), best_t = i, best_f = f;
        }
        continue;
      }
      /* the nearer child on top of the stack */
      a = nd->first, b = nd->first + 1;
      da = gr_mesh_node_distance2(m->nodes + a, p);
      db = gr_mesh_node_distance2(m->nodes + b, p);
      a_first = da <= db;
      dnear = a_first ? da : db, dfar = a_first ? db : da;
      if (dfar < best) stack[top++] = a_first ? b : a;
      if (dnear < best) stack[top++] = a_first ? a : b;
    }
    if (best_t >= 0) break;
    box = GR_MESH_DSQRT(gr_mesh_box_distance2(m->lo, m->hi, p));
    if (m->closed && box == 0 && GR_MESH_ISFINITE(cap)) {
      cap = INFINITY;
      continue;
    }
    if (n) n[0] = 0.0f, n[1] = 1.0f, n[2] = 0.0f;
    return (float)((double)within < box ? box : (double)within);
  }
  if (best_f == GR_MESH_FACE) {
    for (k = 0; k < 3; ++k) pseudo[k] = m->face_n[3 * best_t + k];
  } else if (best_f < GR_MESH_EDGE0) {
    const int v = m->tri[3 * best_t + (best_f - GR_MESH_VERTEX0)];
    for (k = 0; k < 3; ++k) pseudo[k] = m->vertex_n[3 * v + k];
  } else {
    for (k = 0; k < 3; ++k) pseudo[k] = m->edge_n[9 * best_t + 3 * (best_f - GR_MESH_EDGE0) + k];
  }
  gr_mesh_sub(p, best_c, away);
  dist = GR_MESH_DSQRT(best);
  side = gr_mesh_dot(away, pseudo);
  /* a shell has no inside: the distance is unsigned, the normal points toward p */
  sign = m->closed && side < 0 ? -1.0 : 1.0;
  if (n) {
    if (dist > 1e-12) {
      for (k = 0; k < 3; ++k) away[k] = away[k] * sign;
      gr_mesh_unit(away, n);
    } else {
      for (k = 0; k < 3; ++k) n[k] = (float)pseudo[k];
    }
  }
  return (float)(sign * dist);
}

#endif /* GRAINS_ENGINE_MESH_QUERY_H */
#endif
