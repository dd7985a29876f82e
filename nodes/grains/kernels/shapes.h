/* Rigid shape matching (help page "Rigid Shape Matching"; Müller et al. 2005, "Meshless
 * deformations based on shape matching"; pbd_research.md §1), a component at a time: the fit
 * that moves every member to its goal, the shift out of the collider planes and the body's
 * friction with them (the stages gr_shape_* below, numbered in the order shapes.cpp and
 * gr_k_shapes run them).
 *
 * A component's work is shared among GR_SHAPE_LANES lanes: lane l takes members b + l,
 * b + l + LANES, ... (b the component's first), writes its partial sums to its row of `parts`
 * (GR_SHAPE_ROW doubles a lane), and one lane folds the rows into row 0 in lane order
 * (gr_shape_fold_*), so that row 0 holds the sums. The host (shapes.cpp) runs the lanes one
 * after another, a device (gr_k_shapes) as the work-items of one work-group with a barrier
 * between stages, the stages that need the whole body (the fold, the rotation, the friction's
 * contacts in turn) made by its first work-item; both call these functions on the
 * same values in the same order, in double precision, without a multiply and an add fused
 * (GR_SHAPES_EXACT: the device's FP_CONTRACT off, the host's file compiled with
 * -ffp-contract=off; OpenCL rounds double division and square root correctly, as the host does):
 * the same floats, bit for bit. Needs double precision (cl_khr_fp64). */
#ifndef GRAINS_KERNELS_SHAPES_H
#define GRAINS_KERNELS_SHAPES_H
#include "params.h"

#ifdef GR_OPENCL
#define GR_SHAPES_EXACT _Pragma("OPENCL FP_CONTRACT OFF")
#define GR_LOCAL __local
#else
#define GR_SHAPES_EXACT
#define GR_LOCAL
#endif

#define GR_SHAPE_LANES 64 /* lanes a component: a device's work-group size */
#define GR_SHAPE_ROW 9    /* doubles of a lane's row of partial sums */

/* The components of two or more grains: component c's members are
 * members[offsets[c], offsets[c + 1]), each with its rest offset from the component's centre
 * (rest, n x 3) and mass (n). collider_normal (a float a plane entry of gr_grains' planes, or
 * null): the penetration each plane's contact has had removed this substep, which the shift
 * adds to and the body's friction takes as its bound. */
typedef struct {
  const GR_GLOBAL gr_uint* offsets;
  const GR_GLOBAL gr_uint* members;
  const GR_GLOBAL float* rest;
  const GR_GLOBAL float* mass;
  GR_GLOBAL float* collider_normal;
} gr_shapes;

/* 3 x 3 matrices in double, row-major: m[3 * row + col] */
GR_INLINE void gr_m3_identity(double* m) {
  int k;
  for (k = 0; k < 9; ++k) m[k] = (k % 4 == 0) ? 1.0 : 0.0;
}

GR_INLINE double gr_m3_det(const double* m) {
  GR_SHAPES_EXACT
  return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
         m[2] * (m[3] * m[7] - m[4] * m[6]);
}

/* the inverse of m (adjugate over determinant) into out; false where m is singular */
GR_INLINE int gr_m3_inverse(const double* m, double* out) {
  GR_SHAPES_EXACT
  const double det = gr_m3_det(m);
  double inv;
  if (!(det != 0.0)) return 0;
  inv = 1.0 / det;
  out[0] = (m[4] * m[8] - m[5] * m[7]) * inv;
  out[1] = (m[2] * m[7] - m[1] * m[8]) * inv;
  out[2] = (m[1] * m[5] - m[2] * m[4]) * inv;
  out[3] = (m[5] * m[6] - m[3] * m[8]) * inv;
  out[4] = (m[0] * m[8] - m[2] * m[6]) * inv;
  out[5] = (m[2] * m[3] - m[0] * m[5]) * inv;
  out[6] = (m[3] * m[7] - m[4] * m[6]) * inv;
  out[7] = (m[1] * m[6] - m[0] * m[7]) * inv;
  out[8] = (m[0] * m[4] - m[1] * m[3]) * inv;
  return 1;
}

GR_INLINE void gr_m3_apply(const double* m, const double* x, double* out) {
  GR_SHAPES_EXACT
  int r;
  for (r = 0; r < 3; ++r) out[r] = m[3 * r] * x[0] + m[3 * r + 1] * x[1] + m[3 * r + 2] * x[2];
}

GR_INLINE void gr_v3_cross(const double* a, const double* b, double* out) {
  GR_SHAPES_EXACT
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

/* The rotation R of the polar decomposition A = R S (a reflection turned into a rotation
 * through the axis of the smallest singular value, as the fit wants it), by one-sided Jacobi:
 * plane rotations V on the right make the columns of A V orthogonal (A V = U D), and R = U V^T.
 * A column whose length vanishes beside the largest (a flat or straight component) takes a unit
 * direction square to the others: the goals do not depend on it, since every rest offset lies
 * in the span of the other columns of V. A zero A (no spread) gives the identity. */
GR_INLINE void gr_shape_rotation(const double* A, double* R) {
  GR_SHAPES_EXACT
  double a[9], v[9], u[9], len[3];
  int k, sweep, order[3];
  for (k = 0; k < 9; ++k) a[k] = A[k];
  gr_m3_identity(v);
  for (sweep = 0; sweep < 24; ++sweep) {
    int turned = 0, pq;
    for (pq = 0; pq < 3; ++pq) {
      const int p = pq == 2 ? 1 : 0, q = pq == 0 ? 1 : 2;
      double alpha = 0.0, beta = 0.0, gamma = 0.0, zeta, t, c, s;
      for (k = 0; k < 3; ++k) {
        alpha += a[3 * k + p] * a[3 * k + p];
        beta += a[3 * k + q] * a[3 * k + q];
        gamma += a[3 * k + p] * a[3 * k + q];
      }
      if (!(fabs(gamma) > 1e-15 * sqrt(alpha * beta))) continue;
      zeta = (beta - alpha) / (2.0 * gamma);
      t = (zeta >= 0.0 ? 1.0 : -1.0) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
      c = 1.0 / sqrt(1.0 + t * t);
      s = c * t;
      for (k = 0; k < 3; ++k) {
        const double ap = a[3 * k + p], aq = a[3 * k + q];
        const double vp = v[3 * k + p], vq = v[3 * k + q];
        a[3 * k + p] = c * ap - s * aq;
        a[3 * k + q] = s * ap + c * aq;
        v[3 * k + p] = c * vp - s * vq;
        v[3 * k + q] = s * vp + c * vq;
      }
      turned = 1;
    }
    if (!turned) break;
  }
  for (k = 0; k < 3; ++k) len[k] = sqrt(a[k] * a[k] + a[3 + k] * a[3 + k] + a[6 + k] * a[6 + k]);
  /* columns by length, longest first (ties in column order) */
  order[0] = 0, order[1] = 1, order[2] = 2;
  for (k = 0; k < 2; ++k) {
    int j;
    for (j = 0; j < 2 - k; ++j)
      if (len[order[j + 1]] > len[order[j]]) {
        const int swap = order[j];
        order[j] = order[j + 1];
        order[j + 1] = swap;
      }
  }
  if (!(len[order[0]] > 0.0)) {
    gr_m3_identity(R);
    return;
  }
  {
    const int c0 = order[0], c1 = order[1], c2 = order[2];
    double u0[3], u1[3], u2[3], d, vt[9];
    int r, col;
    for (k = 0; k < 3; ++k) u0[k] = a[3 * k + c0] / len[c0];
    /* the second direction: its column less its part along the first, or, where that is lost
     * in rounding, the axis least along the first made square to it */
    for (k = 0; k < 3; ++k) u1[k] = a[3 * k + c1];
    d = u1[0] * u0[0] + u1[1] * u0[1] + u1[2] * u0[2];
    for (k = 0; k < 3; ++k) u1[k] -= d * u0[k];
    d = sqrt(u1[0] * u1[0] + u1[1] * u1[1] + u1[2] * u1[2]);
    if (!(d > 1e-9 * len[c0])) {
      int axis = 0;
      for (k = 1; k < 3; ++k)
        if (fabs(u0[k]) < fabs(u0[axis])) axis = k;
      for (k = 0; k < 3; ++k) u1[k] = (k == axis ? 1.0 : 0.0) - u0[axis] * u0[k];
      d = sqrt(u1[0] * u1[0] + u1[1] * u1[1] + u1[2] * u1[2]);
    }
    for (k = 0; k < 3; ++k) u1[k] /= d;
    /* the third square to both, signed so that R is a rotation: det U = det V */
    gr_v3_cross(u0, u1, u2);
    {
      double vcols[9];
      for (k = 0; k < 3; ++k) {
        vcols[3 * k] = v[3 * k + c0];
        vcols[3 * k + 1] = v[3 * k + c1];
        vcols[3 * k + 2] = v[3 * k + c2];
      }
      if (gr_m3_det(vcols) < 0.0)
        for (k = 0; k < 3; ++k) u2[k] = -u2[k];
    }
    for (k = 0; k < 3; ++k) {
      u[3 * k + c0] = u0[k];
      u[3 * k + c1] = u1[k];
      u[3 * k + c2] = u2[k];
    }
    /* R = U V^T */
    for (k = 0; k < 9; ++k) vt[k] = v[3 * (k % 3) + k / 3];
    for (r = 0; r < 3; ++r)
      for (col = 0; col < 3; ++col)
        R[3 * r + col] =
            u[3 * r] * vt[col] + u[3 * r + 1] * vt[3 + col] + u[3 * r + 2] * vt[6 + col];
  }
}

GR_INLINE void gr_shape_load(const GR_GLOBAL float* a, gr_uint i, double* out) {
  out[0] = (double)a[3 * i];
  out[1] = (double)a[3 * i + 1];
  out[2] = (double)a[3 * i + 2];
}

GR_INLINE void gr_shape_store(GR_GLOBAL float* a, gr_uint i, const double* x) {
  a[3 * i] = (float)x[0];
  a[3 * i + 1] = (float)x[1];
  a[3 * i + 2] = (float)x[2];
}

/* The lanes component c uses: one a member, at most GR_SHAPE_LANES (a lane beyond them has no
 * member and folds nothing) */
GR_INLINE int gr_shape_lanes(const gr_shapes* s, gr_uint c) {
  const gr_uint members = s->offsets[c + 1] - s->offsets[c];
  return members < GR_SHAPE_LANES ? (int)members : GR_SHAPE_LANES;
}

/* The fold, made by one lane: rows 1 to lanes - 1 added into row 0 in turn (values doubles of
 * each) */
GR_INLINE void gr_shape_fold_sum(GR_LOCAL double* parts, int values, int lanes) {
  GR_SHAPES_EXACT
  int l, k;
  for (l = 1; l < lanes; ++l)
    for (k = 0; k < values; ++k) parts[k] += parts[GR_SHAPE_ROW * l + k];
}

/* ... of the shift's bounds: the largest of values 0-2, the smallest of 3-5 */
GR_INLINE void gr_shape_fold_bounds(GR_LOCAL double* parts, int lanes) {
  int l, k;
  for (l = 1; l < lanes; ++l)
    for (k = 0; k < 6; ++k) {
      const double mine = parts[k], other = parts[GR_SHAPE_ROW * l + k];
      parts[k] = (k < 3) == (other > mine) ? other : mine;
    }
}

/* Stage 1, lane l: its members' sum_i m_i p_i (0-2), sum_i m_i rbar_i (3-5) and sum_i m_i (6) */
GR_INLINE void gr_shape_mass_lane(const gr_shapes* s, const GR_GLOBAL float* p, gr_uint c, int l,
                                  GR_LOCAL double* parts) {
  GR_SHAPES_EXACT
  const gr_uint e = s->offsets[c + 1];
  double sum[7] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  gr_uint k;
  int r;
  for (k = s->offsets[c] + (gr_uint)l; k < e; k += GR_SHAPE_LANES) {
    const gr_uint i = s->members[k];
    const double m = (double)s->mass[i];
    double x[3], o[3];
    gr_shape_load(p, i, x);
    gr_shape_load(s->rest, i, o);
    for (r = 0; r < 3; ++r) {
      sum[r] += m * x[r];
      sum[3 + r] += m * o[r];
    }
    sum[6] += m;
  }
  for (r = 0; r < 7; ++r) parts[GR_SHAPE_ROW * l + r] = sum[r];
}

/* the centre (0-2) and the rest offsets' weighted mean (3-5) from stage 1's folded sums. The
 * rest offsets' own mean (float offsets do not sum to 0 exactly): measured from it, the goals
 * keep the centre where it is. Without it each projection moved a body at rest by the offsets'
 * rounding, and 20 projections a substep at 256 substeps a frame drove a free cube of 512 grains
 * to 13 m/s in one frame. */
GR_INLINE void gr_shape_means(const GR_LOCAL double* sums, double* means) {
  GR_SHAPES_EXACT
  int r;
  for (r = 0; r < 6; ++r) means[r] = sums[r] / sums[6];
}

/* Stage 2, lane l: its members' part of A = sum_i m_i (p_i - centre)(rbar_i - rest_mean)^T */
GR_INLINE void gr_shape_fit_lane(const gr_shapes* s, const GR_GLOBAL float* p, gr_uint c, int l,
                                 const double* means, GR_LOCAL double* parts) {
  GR_SHAPES_EXACT
  const gr_uint e = s->offsets[c + 1];
  double A[9] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  gr_uint k;
  int r, col;
  for (k = s->offsets[c] + (gr_uint)l; k < e; k += GR_SHAPE_LANES) {
    const gr_uint i = s->members[k];
    const double m = (double)s->mass[i];
    double x[3], o[3];
    gr_shape_load(p, i, x);
    gr_shape_load(s->rest, i, o);
    for (r = 0; r < 3; ++r) {
      const double dx = m * (x[r] - means[r]);
      for (col = 0; col < 3; ++col) A[3 * r + col] += dx * (o[col] - means[3 + col]);
    }
  }
  for (r = 0; r < 9; ++r) parts[GR_SHAPE_ROW * l + r] = A[r];
}

/* Stage 3, one lane: the rotation R of the folded A (gr_shape_rotation) into rot */
GR_INLINE void gr_shape_fit_rotation(const GR_LOCAL double* A_sum, GR_LOCAL double* rot) {
  double A[9], R[9];
  int r;
  for (r = 0; r < 9; ++r) A[r] = A_sum[r];
  gr_shape_rotation(A, R);
  for (r = 0; r < 9; ++r) rot[r] = R[r];
}

/* ... then lane l: its members to their goals, centre + R (rbar_i - rest_mean) */
GR_INLINE void gr_shape_goal_lane(const gr_shapes* s, GR_GLOBAL float* p, gr_uint c, int l,
                                  const double* means, const GR_LOCAL double* rot) {
  GR_SHAPES_EXACT
  const gr_uint e = s->offsets[c + 1];
  double R[9];
  gr_uint k;
  int r;
  for (r = 0; r < 9; ++r) R[r] = rot[r];
  for (k = s->offsets[c] + (gr_uint)l; k < e; k += GR_SHAPE_LANES) {
    const gr_uint i = s->members[k];
    double o[3], goal[3];
    gr_shape_load(s->rest, i, o);
    for (r = 0; r < 3; ++r) o[r] -= means[3 + r];
    gr_m3_apply(R, o, goal);
    for (r = 0; r < 3; ++r) goal[r] += means[r];
    gr_shape_store(p, i, goal);
  }
}

/* Stage 4 (with collider planes, g's rows), lane l: the largest positive (0-2) and negative
 * (3-5) shift per axis its members' planes ask for, and, where friction (s->collider_normal),
 * each penetration added to its plane's normal sum. The component is then translated out of
 * its planes as a whole (gr_shape_shift_apply). Without that shift a body that lands on a
 * corner could only be pushed out through that corner grain's correction, diluted over the
 * component by the fit (1/N of it per iteration): it would sink, and the final collision pass,
 * grain by grain, would bend it (9% of the side for a 1,000-grain cube). */
GR_INLINE void gr_shape_shift_lane(const gr_shapes* s, const gr_grains* g, const gr_params* prm,
                                   const GR_GLOBAL float* p, gr_uint c, int l,
                                   GR_LOCAL double* parts) {
  GR_SHAPES_EXACT
  const int friction = s->collider_normal != GR_NULL && prm->friction_with_colliders > 0.0f;
  const gr_uint end = s->offsets[c + 1];
  float up[3] = {0.0f, 0.0f, 0.0f}, down[3] = {0.0f, 0.0f, 0.0f};
  gr_uint k, e;
  int r;
  for (k = s->offsets[c] + (gr_uint)l; k < end; k += GR_SHAPE_LANES) {
    const gr_uint i = s->members[k];
    const gr_float3 x = gr_load3(p, (int)i);
    for (e = g->plane_offsets[i]; e < g->plane_offsets[i + 1]; ++e) {
      const GR_GLOBAL float* pl = g->plane + 9 * e;
      const gr_float3 xs = gr_load3(pl, 0), nrm = gr_load3(pl, 1);
      const gr_float3 rel = gr_sub(x, xs);
      const float d = (g->radius ? g->radius[i] : g->uniform_radius) -
                      (rel.x * nrm.x + rel.y * nrm.y + rel.z * nrm.z);
      float m[3];
      if (!(d > 0.0f)) continue;
      if (friction) s->collider_normal[e] += d;
      m[0] = nrm.x * d, m[1] = nrm.y * d, m[2] = nrm.z * d;
      for (r = 0; r < 3; ++r) {
        up[r] = m[r] > up[r] ? m[r] : up[r];
        down[r] = m[r] < down[r] ? m[r] : down[r];
      }
    }
  }
  for (r = 0; r < 3; ++r) {
    parts[GR_SHAPE_ROW * l + r] = (double)up[r];
    parts[GR_SHAPE_ROW * l + 3 + r] = (double)down[r];
  }
}

/* ... lane l's members moved by the folded bounds' shift (up + down, in float) */
GR_INLINE void gr_shape_shift_apply(const gr_shapes* s, GR_GLOBAL float* p, gr_uint c, int l,
                                    const GR_LOCAL double* bounds) {
  const gr_uint e = s->offsets[c + 1];
  const float sx = (float)bounds[0] + (float)bounds[3], sy = (float)bounds[1] + (float)bounds[4],
              sz = (float)bounds[2] + (float)bounds[5];
  gr_uint k;
  if (sx == 0.0f && sy == 0.0f && sz == 0.0f) return;
  for (k = s->offsets[c] + (gr_uint)l; k < e; k += GR_SHAPE_LANES) {
    const gr_uint i = s->members[k];
    const gr_float3 x = gr_load3(p, (int)i);
    gr_store3(p, (int)i, gr_make3(x.x + sx, x.y + sy, x.z + sz));
  }
}

/* Collider friction of the component as a rigid body (help page "Friction: With Colliders", the
 * law of kernels/collider.h: slip below static_threshold x mu x the normal sum is stopped, above
 * it scale_kinetic x mu x the normal sum of it is taken out), applied to the body, not to its
 * contact grains: a grain's own friction moves only that grain, and the fit passes on 1/N of it,
 * so a 843-grain rock slid down a 25 degree slope it should have rolled down (10 degrees of turn
 * in 4 s). Stage 5, lane l: sum_i m_i p_i (0-2), sum_i m_i (3) and its members' touching
 * contacts (4: a contact is touching where its normal sum is above 0). */
GR_INLINE void gr_shape_body_lane(const gr_shapes* s, const gr_grains* g, const GR_GLOBAL float* p,
                                  gr_uint c, int l, GR_LOCAL double* parts) {
  GR_SHAPES_EXACT
  const gr_uint end = s->offsets[c + 1];
  double sum[5] = {0.0, 0.0, 0.0, 0.0, 0.0};
  gr_uint k, e;
  int r;
  for (k = s->offsets[c] + (gr_uint)l; k < end; k += GR_SHAPE_LANES) {
    const gr_uint i = s->members[k];
    const double m = (double)s->mass[i];
    double x[3];
    gr_shape_load(p, i, x);
    for (r = 0; r < 3; ++r) sum[r] += m * x[r];
    sum[3] += m;
    for (e = g->plane_offsets[i]; e < g->plane_offsets[i + 1]; ++e)
      sum[4] += s->collider_normal[e] > 0.0f ? 1.0 : 0.0;
  }
  for (r = 0; r < 5; ++r) parts[GR_SHAPE_ROW * l + r] = sum[r];
}

/* the body's centre from stage 5's folded sums */
GR_INLINE void gr_shape_centre(const GR_LOCAL double* sums, double* centre) {
  GR_SHAPES_EXACT
  int r;
  for (r = 0; r < 3; ++r) centre[r] = sums[r] / sums[3];
}

/* Stage 6, lane l: its members' part of the inertia about the centre (body: stage 5's sums) */
GR_INLINE void gr_shape_inertia_lane(const gr_shapes* s, const GR_GLOBAL float* p, gr_uint c, int l,
                                     const double* centre, GR_LOCAL double* parts) {
  GR_SHAPES_EXACT
  const gr_uint end = s->offsets[c + 1];
  double inertia[9] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  gr_uint k;
  int r, col;
  for (k = s->offsets[c] + (gr_uint)l; k < end; k += GR_SHAPE_LANES) {
    const gr_uint i = s->members[k];
    const double m = (double)s->mass[i];
    double x[3], d[3], d2;
    gr_shape_load(p, i, x);
    for (r = 0; r < 3; ++r) d[r] = x[r] - centre[r];
    d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    for (r = 0; r < 3; ++r)
      for (col = 0; col < 3; ++col)
        inertia[3 * r + col] += m * ((r == col ? d2 : 0.0) - d[r] * d[col]);
  }
  for (r = 0; r < 9; ++r) parts[GR_SHAPE_ROW * l + r] = inertia[r];
}

/* Stage 7, one lane: each touching contact in turn (Gauss-Seidel, in member order) gets the
 * impulse J = K^-1 D that changes its point's slip by D, K = 1/M - [r]x I^-1 [r]x the body's
 * compliance at r; the body's translation J / M (out 0-2) and rotation I^-1 (r x J) (out 3-5)
 * add up, to move every member once, linearised (gr_shape_friction_apply; the next fit restores
 * the exact rigid shape). centre: the body's centre, mass its mass, inertia_sum the folded
 * inertia. */
GR_INLINE void gr_shape_friction(const gr_shapes* s, const gr_grains* g, const gr_params* prm,
                                 const GR_GLOBAL float* p, gr_uint c, const double* centre,
                                 double mass, const GR_LOCAL double* inertia_sum, double* out) {
  GR_SHAPES_EXACT
  const gr_uint e_end = s->offsets[c + 1];
  double inertia[9], inv_inertia[9], trace;
  double move[3] = {0.0, 0.0, 0.0}, turn[3] = {0.0, 0.0, 0.0};
  gr_uint k, e;
  int r;
  for (r = 0; r < 6; ++r) out[r] = 0.0;
  for (r = 0; r < 9; ++r) inertia[r] = inertia_sum[r];
  /* a line of grains has no inertia about its axis: a trace-relative floor keeps I invertible */
  trace = inertia[0] + inertia[4] + inertia[8];
  for (r = 0; r < 3; ++r) inertia[4 * r] += 1e-6 * trace;
  if (!gr_m3_inverse(inertia, inv_inertia)) return;
  for (k = s->offsets[c]; k < e_end; ++k) {
    const gr_uint i = s->members[k];
    const double mu =
        (double)prm->friction_with_colliders * (double)(g->friction ? g->friction[i] : 1.0f);
    double x[3], d[3], start[3];
    if (g->plane_offsets[i] == g->plane_offsets[i + 1]) continue;
    gr_shape_load(p, i, x);
    gr_shape_load(g->P, i, start);
    for (r = 0; r < 3; ++r) d[r] = x[r] - centre[r];
    for (e = g->plane_offsets[i]; e < g->plane_offsets[i + 1]; ++e) {
      const GR_GLOBAL float* pl = g->plane + 9 * e;
      double n[3], tw[3], sl[3], along, length, bound, keep, want[3], K[9], Kinv[9], J[3], rJ[3];
      double sk[9], t1[9], dturn[3], kinetic;
      int col, q;
      if (!(s->collider_normal[e] > 0.0f)) continue;
      for (r = 0; r < 3; ++r) n[r] = (double)pl[3 + r];
      /* the contact point's slip over the substep, relative to the collider's own motion */
      gr_v3_cross(turn, d, tw);
      for (r = 0; r < 3; ++r)
        sl[r] = (x[r] + move[r] + tw[r]) - start[r] - (double)pl[6 + r] * (double)prm->dt;
      along = n[0] * sl[0] + n[1] * sl[1] + n[2] * sl[2];
      for (r = 0; r < 3; ++r) sl[r] -= n[r] * along;
      length = sqrt(sl[0] * sl[0] + sl[1] * sl[1] + sl[2] * sl[2]);
      if (!(length > 0.0)) continue;
      bound = mu * (double)s->collider_normal[e];
      if (length < (double)prm->static_threshold * bound) {
        keep = 0.0;
      } else {
        kinetic = (double)prm->scale_kinetic * bound / length;
        keep = 1.0 - (kinetic < 1.0 ? kinetic : 1.0);
      }
      if (keep >= 1.0) continue;
      for (r = 0; r < 3; ++r) want[r] = -sl[r] * (1.0 - keep);
      /* K = 1/M - [d]x I^-1 [d]x */
      sk[0] = 0.0, sk[1] = -d[2], sk[2] = d[1];
      sk[3] = d[2], sk[4] = 0.0, sk[5] = -d[0];
      sk[6] = -d[1], sk[7] = d[0], sk[8] = 0.0;
      for (r = 0; r < 3; ++r)
        for (col = 0; col < 3; ++col) {
          double sum = 0.0;
          for (q = 0; q < 3; ++q) sum += inv_inertia[3 * r + q] * sk[3 * q + col];
          t1[3 * r + col] = sum;
        }
      for (r = 0; r < 3; ++r)
        for (col = 0; col < 3; ++col) {
          double sum = 0.0;
          for (q = 0; q < 3; ++q) sum += sk[3 * r + q] * t1[3 * q + col];
          K[3 * r + col] = (r == col ? 1.0 / mass : 0.0) - sum;
        }
      if (!gr_m3_inverse(K, Kinv)) continue;
      gr_m3_apply(Kinv, want, J);
      for (r = 0; r < 3; ++r) move[r] += J[r] / mass;
      gr_v3_cross(d, J, rJ);
      gr_m3_apply(inv_inertia, rJ, dturn);
      for (r = 0; r < 3; ++r) turn[r] += dturn[r];
    }
  }
  for (r = 0; r < 3; ++r) {
    out[r] = move[r];
    out[3 + r] = turn[r];
  }
}

/* ... lane l's members moved by the body's translation and rotation (motion: stage 7's out) */
GR_INLINE void gr_shape_friction_apply(const gr_shapes* s, GR_GLOBAL float* p, gr_uint c, int l,
                                       const double* centre, const GR_LOCAL double* motion) {
  GR_SHAPES_EXACT
  const gr_uint e = s->offsets[c + 1];
  double turn[3];
  gr_uint k;
  int r;
  for (r = 0; r < 3; ++r) turn[r] = motion[3 + r];
  for (k = s->offsets[c] + (gr_uint)l; k < e; k += GR_SHAPE_LANES) {
    const gr_uint i = s->members[k];
    double x[3], d[3], tw[3];
    gr_shape_load(p, i, x);
    for (r = 0; r < 3; ++r) d[r] = x[r] - centre[r];
    gr_v3_cross(turn, d, tw);
    for (r = 0; r < 3; ++r) x[r] += motion[r] + tw[r];
    gr_shape_store(p, i, x);
  }
}

#endif /* GRAINS_KERNELS_SHAPES_H */
