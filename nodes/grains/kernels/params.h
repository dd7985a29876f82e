/* Plain-data inputs of the grains kernels: the substep's parameters (gr_params, filled once per
 * substep from GrainsSettings) and the per-grain arrays they read (gr_grains). Optional point
 * attributes are null when missing; gr_attr() then reads 1. */
#ifndef GRAINS_KERNELS_PARAMS_H
#define GRAINS_KERNELS_PARAMS_H
#include "prelude.h"

/* contact planes kept per grain (FleX keeps six; corners of boxes need three) */
#define GR_MAX_PLANES 4

typedef struct {
  /* the KERNEL rows of param_table.h, as the graph names them */
#define GR_KERNEL_TYPE_FLOAT float
#define GR_KERNEL_TYPE_INT int
#define GR_KERNEL_TYPE_TOGGLE int
#define GR_KERNEL_FIELD_KERNEL(kind, name) GR_KERNEL_TYPE_##kind name;
#define GR_KERNEL_FIELD_HOST(kind, name)
#define GR_PARAM(kind, name, def, home, modifiers, meaning) GR_KERNEL_FIELD_##home(kind, name)
#include "param_table.h"
#undef GR_PARAM
#undef GR_KERNEL_FIELD_HOST
#undef GR_KERNEL_FIELD_KERNEL
  /* derived each substep (solver.cpp make_params) */
  float dt;                    /* substep length (s) */
  float stiffness_denominator; /* substeps * constraint_iterations: k -> min(1, k / this) */
  /* mass-shock scaling: 0 off, 1 global (inv_mass holds 1/shockmass), 2 local */
  int mass_shock;
  float shock_power;          /* local: already clamped to 7 */
  float shock_inv_separation; /* 1 / particle_separation (1/m) */
  float shock_axis_x, shock_axis_y, shock_axis_z; /* unit */
  float shock_origin_x, shock_origin_y, shock_origin_z;
} gr_params;

typedef struct {
  const GR_GLOBAL float* P;        /* (n x 3) m, start of substep */
  /* (neighbour entries x 3) m, or null: each contact's slip left over from earlier substeps
   * (contact history, GrainsSolver::save_history) */
  const GR_GLOBAL float* pair_slip;
  /* (plane entries x 3) m, or null: the same for each collider plane */
  const GR_GLOBAL float* plane_slip;
  const GR_GLOBAL float* v;        /* (n x 3) m/s, start of substep */
  const GR_GLOBAL float* force;    /* (n x 3) N, or (points x 3) read through force_index */
  const GR_GLOBAL gr_uint* force_index; /* (n) optional: grain i's row of force */
  int force_uniform; /* 1: every grain's force is force's first row (a device's one-row copy) */
  const GR_GLOBAL float* mass;     /* (n) kg */
  const GR_GLOBAL float* radius;   /* (n) m */
  const GR_GLOBAL float* inv_mass; /* (n) 1/kg: 1/mass, or 1/shockmass with global mass-shock */
  /* > 0 when every grain has this radius and this inverse mass (equal grains, no global
   * mass-shock): the contact loop then reads neither array per candidate. 0 otherwise. */
  float uniform_radius;
  float uniform_inv_mass;
  const GR_GLOBAL float* friction;            /* (n) optional */
  const GR_GLOBAL float* repulsionweight;     /* (n) optional */
  const GR_GLOBAL float* repulsionstiffness;  /* (n) optional */
  const GR_GLOBAL float* attractionweight;    /* (n) optional */
  const GR_GLOBAL float* attractionstiffness; /* (n) optional */
  const GR_GLOBAL gr_uint* nbr_offsets;       /* (n + 1) neighbour rows, or null: no pairs */
  const GR_GLOBAL gr_uint* nbr_indices;
  /* 1 when the rows already leave out every pair joined by an explicit constraint (the host
   * drops them once per search when mutually constrained grains do not collide), so the
   * contact loop need not look each pair up in the constraint adjacency */
  int nbr_unconstrained;
  /* collider contact planes: row i lists grain i's planes (at most GR_MAX_PLANES, nearest
   * first), entries [plane_offsets[i], plane_offsets[i + 1]) of `plane`, 9 floats each: surface
   * point (m), unit normal, surface velocity (m/s). Stored compactly: a grain far from every
   * collider costs one offset. Both null when there are no colliders. */
  const GR_GLOBAL gr_uint* plane_offsets; /* (n + 1) */
  const GR_GLOBAL float* plane;           /* (entries x 9) */
  /* explicit constraints: row i of the adjacency lists i's constraints, other endpoint
   * con_other[k] and primitive con_prim[k], k in [con_offsets[i], con_offsets[i + 1]), in
   * primitive order. Null when the constraint weight is 0 or there are no constraints. */
  const GR_GLOBAL gr_uint* con_offsets;       /* (n + 1) */
  const GR_GLOBAL gr_uint* con_other;         /* (2 m) */
  const GR_GLOBAL gr_uint* con_prim;          /* (2 m) */
  const GR_GLOBAL float* restlength;          /* (m) m, per primitive */
  const GR_GLOBAL float* constraintweight;    /* (n) optional */
  const GR_GLOBAL float* constraintstiffness; /* (n) optional */
  /* pins: null when off. targetstiffness is required when targetP is set (missing = no pin) */
  const GR_GLOBAL float* targetP;         /* (n x 3) m */
  const GR_GLOBAL float* targetweight;    /* (n) optional */
  const GR_GLOBAL float* targetstiffness; /* (n) */
} gr_grains;

#endif /* GRAINS_KERNELS_PARAMS_H */
