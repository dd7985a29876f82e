/* The grains kernels as one OpenCL C 1.2 program: every shared header (nodes/grains/kernels/,
 * the same code the CPU path compiles) and the kernels of the substep's stages that run on a
 * device (opencl/iterations.cpp launches them; GrainsSolver::substep runs the rest). `grains
 * devices` builds this program on each device it lists, and the ctest opencl_kernels_compile
 * compiles it to SPIR with clang, so that code generation, not only parsing, sees it. */
#include "clumping.h"
#include "collider.h"
#include "contact.h"
#include "distance.h"
#include "final_collision.h"
#include "history.h"
#include "impact.h"
#include "iterate.h"
#include "mass_shock.h"
#include "params.h"
#include "pin.h"
#include "planes.h"
#include "sequential.h"
#include "velocity.h"
#include "warm.h"

/* The per-grain arrays of gr_grains as kernel arguments (a kernel argument cannot hold pointers
 * in OpenCL C 1.2), in the order opencl/iterations.cpp sets them; a missing one is null, as on
 * the CPU. */
#define GR_GRAINS_ARGS                                                                        \
  __global const float *P, __global const float *radius, __global const float *inv_mass,     \
      __global const float *mass, __global const float *friction,                             \
      __global const float *repulsionweight, __global const float *repulsionstiffness,        \
      __global const float *attractionweight, __global const float *attractionstiffness,      \
      __global const gr_uint *nbr_offsets, __global const gr_uint *nbr_indices,               \
      __global const float *pair_slip, __global const gr_uint *plane_offsets,                 \
      __global const float *plane, __global const float *plane_slip,                          \
      __global const gr_uint *con_offsets, __global const gr_uint *con_other,                 \
      __global const gr_uint *con_prim, __global const float *restlength,                     \
      __global const float *constraintweight, __global const float *constraintstiffness,      \
      float uniform_radius, float uniform_inv_mass, int nbr_unconstrained

GR_INLINE gr_grains gr_device_grains(GR_GRAINS_ARGS) {
  gr_grains g = {0};
  g.P = P;
  g.radius = radius;
  g.inv_mass = inv_mass;
  g.mass = mass;
  g.friction = friction;
  g.repulsionweight = repulsionweight;
  g.repulsionstiffness = repulsionstiffness;
  g.attractionweight = attractionweight;
  g.attractionstiffness = attractionstiffness;
  g.nbr_offsets = nbr_offsets;
  g.nbr_indices = nbr_indices;
  g.pair_slip = pair_slip;
  g.plane_offsets = plane_offsets;
  g.plane = plane;
  g.plane_slip = plane_slip;
  g.con_offsets = con_offsets;
  g.con_other = con_other;
  g.con_prim = con_prim;
  g.restlength = restlength;
  g.constraintweight = constraintweight;
  g.constraintstiffness = constraintstiffness;
  g.uniform_radius = uniform_radius;
  g.uniform_inv_mass = uniform_inv_mass;
  g.nbr_unconstrained = nbr_unconstrained;
  return g;
}

#define GR_GRAINS_NAMES                                                                       \
  P, radius, inv_mass, mass, friction, repulsionweight, repulsionstiffness, attractionweight, \
      attractionstiffness, nbr_offsets, nbr_indices, pair_slip, plane_offsets, plane,         \
      plane_slip, con_offsets, con_other, con_prim, restlength, constraintweight,             \
      constraintstiffness, uniform_radius, uniform_inv_mass, nbr_unconstrained

/* The sums the iterations keep for the friction pass and the impact data (gr_normal_sums);
 * `scratch` holds each grain's row of this iteration's overlaps, row_length floats a grain (the
 * CPU keeps one such row a thread). */
GR_INLINE gr_normal_sums gr_device_sums(__global float* scratch, gr_uint row_length, int i,
                                        __global gr_uint* pair_sum, __global float* collider_sum,
                                        __global float* collider_dx, __global float* friction_dx) {
  gr_normal_sums acc;
  acc.pair_iteration = scratch ? scratch + (size_t)row_length * (size_t)i : 0;
  acc.pair = pair_sum;
  acc.collider = collider_sum;
  acc.collider_dx = collider_dx;
  acc.friction_dx = friction_dx;
  return acc;
}

/* one Jacobi iteration: next = gr_iterate(p), grain by grain (DESIGN §4 step 3) */
__kernel void gr_k_iterate(gr_params prm, GR_GRAINS_ARGS, __global const float* p,
                           __global float* next, __global float* scratch, gr_uint row_length,
                           __global gr_uint* pair_sum, __global float* collider_sum,
                           __global float* collider_dx, __global float* friction_dx, int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
  const gr_normal_sums acc =
      gr_device_sums(scratch, row_length, i, pair_sum, collider_sum, collider_dx, friction_dx);
  gr_store3(next, i, gr_iterate(&g, &prm, p, i, &acc));
}

/* the friction pass: next = gr_friction_pass(p) */
__kernel void gr_k_friction(gr_params prm, GR_GRAINS_ARGS, __global const float* p,
                            __global float* next, __global gr_uint* pair_sum,
                            __global float* collider_sum, __global float* collider_dx,
                            __global float* friction_dx, int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
  const gr_normal_sums acc = gr_device_sums(0, 0, i, pair_sum, collider_sum, collider_dx, friction_dx);
  gr_store3(next, i, gr_friction_pass(&g, &prm, p, &acc, i));
}

/* A colour's sweep: work-group t sweeps block blocks[first + t] (count in all), its waves
 * [*begin, *end) (GrainsSolver::order_waves) one after another, the group's work-items sharing
 * out each wave's contacts (GR_WAVE) and meeting at a barrier after it. No two contacts of a
 * wave move one grain, so the result is the CPU's sweep's whatever the group's size and
 * schedule. 0 for a work-group past the colour's blocks (the whole group returns). */
GR_INLINE int gr_sweep_block(int first, int count, __global const gr_uint* blocks,
                             __global const gr_uint* block_wave, gr_uint* begin, gr_uint* end) {
  const int t = (int)get_group_id(0);
  gr_uint b;
  if (t >= count) return 0;
  b = blocks[first + t];
  *begin = block_wave[b];
  *end = block_wave[b + 1];
  return 1;
}

/* the contacts k of wave w this work-item takes */
#define GR_WAVE(k, w, wave_start)                                                  \
  for (k = wave_start[w] + (gr_uint)get_local_id(0); k < wave_start[(w) + 1];      \
       k += (gr_uint)get_local_size(0))

/* gauss_seidel's warm start (kernels/warm.h; solve_sequential in opencl/iterations.cpp launches
 * these in gauss_seidel.cpp's order). Per contact, part by part where the contacts are split
 * over buffers: work-item t has contact k = base + t, at seq[t], its normal and factor in the
 * part's normal[3 t ...] and factor[t] (loaded is one array over all the contacts). */
__kernel void gr_k_warm_open(gr_params prm, GR_GRAINS_ARGS, __global const float* p,
                             __global gr_seq_contact* seq, gr_uint base, int count,
                             __global const uchar* loaded, __global float* normal,
                             __global float* factor) {
  const int t = (int)get_global_id(0);
  size_t k;
  if (t >= count) return;
  k = base + (size_t)t;
  if (!loaded[k]) {
    factor[t] = 0.0f;
    normal[3 * t] = normal[3 * t + 1] = normal[3 * t + 2] = 0.0f;
    return;
  }
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    factor[t] = gr_warm_open(&g, p, seq + t, normal + 3 * (size_t)t);
  }
}

/* a kept list's loads where the device holds it (gr_seq_keep): work-item t has contact base + t,
 * at seq[t]; loaded[base + t] (null: none) says whether it carries one */
__kernel void gr_k_keep(__global gr_seq_contact* seq, gr_uint base, int count, int warm,
                        float scale, __global uchar* loaded) {
  const int t = (int)get_global_id(0);
  int carries;
  if (t >= count) return;
  carries = gr_seq_keep(seq + t, warm, scale);
  if (loaded) loaded[base + t] = (uchar)carries;
}

__kernel void gr_k_warm_factor(__global const gr_seq_contact* seq, gr_uint base, int count,
                               __global const float* balance, __global float* factor) {
  const int t = (int)get_global_id(0);
  if (t >= count) return;
  if (factor[t] > 0.0f) factor[t] = gr_warm_factor(seq + t, balance);
}

/* a contact with a grain gone cold starts cold; *cut set when any does */
__kernel void gr_k_warm_cut(__global const gr_seq_contact* seq, gr_uint base, int count,
                            __global const uchar* cold, __global float* factor,
                            __global volatile int* cut) {
  const int t = (int)get_global_id(0);
  __global const gr_seq_contact* q = seq + t;
  if (t >= count) return;
  if (factor[t] > 0.0f && (cold[q->i] || (q->j >= 0 && cold[q->j]))) {
    factor[t] = 0.0f;
    atomic_or(cut, 1);
  }
}

/* per grain: the balance (and the external step), whether it goes cold, and the velocity
 * pre-stabilization takes back */
__kernel void gr_k_warm_balance(gr_params prm, GR_GRAINS_ARGS, __global const float* v,
                                __global const float* p, __global const float* repeat,
                                __global float* external, __global float* balance, int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    g.v = v;
    balance[i] = gr_warm_balance(&g, p, prm.dt, repeat, i, external);
  }
}

__kernel void gr_k_warm_cold(gr_params prm, GR_GRAINS_ARGS, __global const float* repeat,
                             __global const float* external, __global uchar* cold, int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    cold[i] = (uchar)gr_warm_cold(&g, repeat, external, i);
  }
}

__kernel void gr_k_warm_take_back(gr_params prm, GR_GRAINS_ARGS, __global float* v,
                                  __global float* p, __global const float* carried,
                                  float inv_last, int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    gr_warm_take_back(&g, v, p, carried, inv_last, prm.dt, i);
  }
}

/* The substep's prediction (kernels/velocity.h, gr_predict): grain i's predicted position into
 * p, and a zero past the last grain, as an upload of positions has (the contact loop's block
 * loads); v and force as gr_k_finish reads them. The host's floats, bit for bit: gr_fmadd fuses
 * on both. */
__kernel void gr_k_predict(gr_params prm, GR_GRAINS_ARGS, __global const float* v,
                           __global const float* force, int force_uniform, __global float* p,
                           int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  if (i == 0) p[3 * n] = 0.0f;
  {
    gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    g.v = v;
    g.force = force;
    g.force_uniform = force_uniform;
    gr_predict(&g, &prm, p, i);
  }
}

/* The substep's end (kernels/velocity.h, gr_update_velocity): grain i's position written back
 * in world coordinates (the substep's plus the origin, as the host adds them) into P_out and its
 * velocity into v_out (null: the host keeps its own). v: the start velocity as pre-stabilization
 * left it; force: a row a grain, or one row for every grain (force_uniform), or null. */
__kernel void gr_k_finish(gr_params prm, GR_GRAINS_ARGS, __global const float* v,
                          __global const float* force, int force_uniform, __global const float* p,
                          float origin_x, float origin_y, float origin_z, __global float* P_out,
                          __global float* v_out, int n, int keep) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    gr_float3 end, velocity;
    g.v = v;
    g.force = force;
    g.force_uniform = force_uniform;
    gr_update_velocity(&g, &prm, p, i, &end, &velocity);
    if (keep) velocity = gr_load3(v, i); /* a kept start velocity (error control's stabilizing) */
    P_out[3 * i] = end.x + origin_x;
    P_out[3 * i + 1] = end.y + origin_y;
    P_out[3 * i + 2] = end.z + origin_z;
    if (v_out) gr_store3(v_out, i, velocity);
  }
}

/* The final collision test (kernels/final_collision.h) of the substep's end gr_k_finish wrote
 * (P_out, world, and v_out), against `count` colliders in order (0: no test; their meshes in
 * `meshes`, Iterations::set_meshes): grain i moved from its start (start, the substep's
 * coordinates, plus the origin: the host's world start, bit for bit, solver.cpp local_origin). A fixed grain is not tested. With collider_out
 * the impact data beside it (kernels/impact.h): grain i's slots from dx, its plane row and what
 * the test did to it, as GrainsSolver::write_back makes them, into collider_out, impulse, normal
 * and point (GR_MAX_PLANES a grain); null: none. */
__kernel void gr_k_final_collision(gr_params prm, GR_GRAINS_ARGS,
                                   __global const gr_collider* colliders, int count,
                                   __global const float* start, float origin_x, float origin_y,
                                   float origin_z, __global float* P_out, __global float* v_out,
                                   int n, __global const float* dx,
                                   __global const int* plane_collider, __global int* collider_out,
                                   __global float* impulse, __global float* normal,
                                   __global float* point, __global const int* meshes) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    float b[3], v[3], v_loop[3], hit_n[3] = {0.0f, 0.0f, 0.0f};
    int k, hit = -1;
    for (k = 0; k < 3; ++k) b[k] = P_out[3 * i + k], v[k] = v_loop[k] = v_out[3 * i + k];
    if (count > 0 && g.inv_mass[i] > 0.0f) {
      const float a[3] = {start[3 * i] + origin_x, start[3 * i + 1] + origin_y,
                          start[3 * i + 2] + origin_z};
      const float mu = prm.friction_with_colliders * gr_attr(g.friction, i);
      hit = gr_final_collisions(colliders, count, a, b, v, g.radius[i], mu, prm.static_threshold,
                                prm.scale_kinetic, hit_n, meshes);
      for (k = 0; k < 3; ++k) P_out[3 * i + k] = b[k], v_out[3 * i + k] = v[k];
    }
    if (collider_out)
      gr_impact_slots(&g, prm.dt, i, dx, plane_collider, b, v, v_loop, hit, hit_n, collider_out,
                      impulse, normal, point);
  }
}

/* gauss_seidel's impact data (kernels/impact.h): each collider contact's loads into its
 * grain's slot of dx (zeroed before), a work-item a contact of a part */
__kernel void gr_k_impact_loads(gr_params prm, GR_GRAINS_ARGS, __global const gr_seq_contact* seq,
                                gr_uint base, int count, __global float* dx) {
  const int k = (int)get_global_id(0);
  (void)prm;
  (void)base;
  if (k >= count) return;
  {
    gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    gr_seq_impact_load(&g, seq + k, dx);
  }
}

/* The slots gr_k_final_collision filled (a collider named), packed for the host: each takes a
 * record at an index an integer counter gives (any order: the host puts each back in its slot),
 * its slot and collider in index (2 a record), its momentum, normal and point in value (9). */
__kernel void gr_k_impact_pack(__global const int* collider, __global const float* impulse,
                               __global const float* normal, __global const float* point,
                               int slots, __global volatile gr_uint* count, __global int* index,
                               __global float* value) {
  const int e = (int)get_global_id(0);
  gr_uint r;
  int k;
  if (e >= slots || collider[e] < 0) return;
  r = atomic_inc(count);
  index[2 * r] = e;
  index[2 * r + 1] = collider[e];
  for (k = 0; k < 3; ++k) {
    value[9 * r + k] = impulse[3 * e + k];
    value[9 * r + 3 + k] = normal[3 * e + k];
    value[9 * r + 6 + k] = point[3 * e + k];
  }
}

/* The substep's start from the last substep's end kept here (Iterations::carry_start): the
 * world positions end_P less the origin into P, as the host takes them (solver.cpp,
 * bind_inputs: the same subtraction), and a zero past the last grain, as an upload of positions
 * has (the contact loop's block loads); the velocities end_v into v (null: not carried). */
__kernel void gr_k_carry(__global const float* end_P, float origin_x, float origin_y,
                         float origin_z, __global float* P, __global const float* end_v,
                         __global float* v, int n, __global const gr_uint* from) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  if (i == 0) P[3 * n] = 0.0f;
  /* grain i was grain from[i] of the last end (none: 0xffffffff, sent alone), or grain i */
  const gr_uint j = from ? from[i] : (gr_uint)i;
  if (j == 0xffffffffu) return;
  P[3 * i] = end_P[3 * j] - origin_x;
  P[3 * i + 1] = end_P[3 * j + 1] - origin_y;
  P[3 * i + 2] = end_P[3 * j + 2] - origin_z;
  if (v) {
    v[3 * i] = end_v[3 * j];
    v[3 * i + 1] = end_v[3 * j + 1];
    v[3 * i + 2] = end_v[3 * j + 2];
  }
}

/* gr_k_end_bounds: over the grains w, w + items, ... of what the end wrote (P, world, and v),
 * the box of the positions whose three coordinates are finite (as solver.cpp's local_origin
 * takes it) and whether a position or a velocity is not: part[7 w ...] = lo, hi, 0 or 1 */
__kernel void gr_k_end_bounds(__global const float* P, __global const float* v, int n,
                              __global float* part) {
  const int w = (int)get_global_id(0), items = (int)get_global_size(0);
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  float bad = 0.0f;
  int i, a;
  for (i = w; i < n; i += items) {
    if (isfinite(P[3 * i]) && isfinite(P[3 * i + 1]) && isfinite(P[3 * i + 2])) {
      for (a = 0; a < 3; ++a) {
        const float x = P[3 * i + a];
        lo[a] = x < lo[a] ? x : lo[a];
        hi[a] = x > hi[a] ? x : hi[a];
      }
    } else {
      bad = 1.0f;
    }
    if (!(isfinite(v[3 * i]) && isfinite(v[3 * i + 1]) && isfinite(v[3 * i + 2]))) bad = 1.0f;
  }
  for (a = 0; a < 3; ++a) part[7 * w + a] = lo[a], part[7 * w + 3 + a] = hi[a];
  part[7 * w + 6] = bad;
}

/* the grains index[k] of P take the positions values[k] (3 floats each), k < count */
__kernel void gr_k_scatter3(__global float* P, __global const gr_uint* index,
                            __global const float* values, int count) {
  const int k = (int)get_global_id(0);
  if (k >= count) return;
  {
    const gr_uint i = index[k];
    P[3 * i] = values[3 * k];
    P[3 * i + 1] = values[3 * k + 1];
    P[3 * i + 2] = values[3 * k + 2];
  }
}

/* block sweeps, colour by colour as the passes: each block's contacts in order add their
 * scaled loads to what their grains receive (repeat), or scale and apply them to p (seq, normal
 * and factor the part's, from contact base on) */
__kernel void gr_k_warm_repeat(__global const gr_seq_contact* seq, __global const gr_uint* block_wave,
                               __global const gr_uint* blocks, int first, int count, gr_uint base,
                               __global const float* normal, __global const float* factor,
                               __global float* repeat, __global const gr_uint* wave_start) {
  gr_uint w, we, k;
  if (!gr_sweep_block(first, count, blocks, block_wave, &w, &we)) return;
  for (; w < we; ++w) {
    GR_WAVE(k, w, wave_start)
    gr_warm_repeat(seq + (k - base), normal + 3 * (size_t)(k - base), factor[k - base], repeat);
    barrier(CLK_GLOBAL_MEM_FENCE);
  }
}

__kernel void gr_k_warm_apply(__global float* p, __global gr_seq_contact* seq,
                              __global const gr_uint* block_wave, __global const gr_uint* blocks,
                              int first, int count, gr_uint base, __global const float* normal,
                              __global const float* factor, __global const gr_uint* wave_start) {
  gr_uint w, we, k;
  if (!gr_sweep_block(first, count, blocks, block_wave, &w, &we)) return;
  for (; w < we; ++w) {
    GR_WAVE(k, w, wave_start)
    gr_warm_apply(p, seq + (k - base), normal + 3 * (size_t)(k - base), factor[k - base]);
    barrier(CLK_GLOBAL_MEM_FENCE);
  }
}

/* what the Jacobi path's pre-stabilization moved the start, added to the predicted positions:
 * out = p + (x - P), float k of `floats`, as GrainsSolver::pre_stabilize adds them */
__kernel void gr_k_shift(__global const float* p, __global const float* x,
                         __global const float* P, __global float* out, int floats) {
  const int k = (int)get_global_id(0);
  if (k >= floats) return;
  out[k] = p[k] + (x[k] - P[k]);
}

/* one pass of the Jacobi path's pre-stabilization: next = gr_stabilize(x), and each grain's
 * move over its radius in moved (the host stops on the largest, gr_k_largest) */
__kernel void gr_k_stabilize_grains(gr_params prm, GR_GRAINS_ARGS, __global const float* x,
                                    __global float* next, __global float* moved, int n) {
  const int i = (int)get_global_id(0);
  gr_float3 y;
  if (i >= n) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    y = gr_stabilize(&g, &prm, x, i);
    moved[i] = gr_length(gr_sub(y, gr_load3(x, i))) / radius[i];
    gr_store3(next, i, y);
  }
}

/* the Jacobi path's contact history (kernels/history.h, opencl/history.cpp): grain i's slips
 * saved at the substep's end into out */
__kernel void gr_k_save_pair_slips(gr_params prm, GR_GRAINS_ARGS, __global const float* p,
                                   __global const gr_uint* pair_normal, __global float* out,
                                   int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    gr_save_pair_slips(&g, &prm, p, pair_normal, i, out);
  }
}

__kernel void gr_k_save_plane_slips(gr_params prm, GR_GRAINS_ARGS, __global const float* p,
                                    __global const float* collider_normal, __global float* out,
                                    int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    gr_save_plane_slips(&g, &prm, p, collider_normal, i, out);
  }
}

/* grain i of the last substep's n at its id in table (filled with -1 before; ids >= 0 and below
 * the table's size; hist_id null: its index) */
__kernel void gr_k_history_table(__global const int* hist_id, int n, __global int* table) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  table[hist_id ? hist_id[i] : i] = i;
}

/* grain i's carried slips, looked up by id in the last substep's rows (gr_load_pair_slips): its
 * index there from table (table_size ids; table null: the same grains in the same order, its
 * own, id and hist_id null) */
__kernel void gr_k_load_pair_slips(__global const gr_uint* offsets, __global const gr_uint* indices,
                                   __global const int* id, __global const int* table,
                                   int table_size, __global const gr_uint* hist_offsets,
                                   __global const gr_uint* hist_indices,
                                   __global const int* hist_id, __global const float* hist_slip,
                                   __global float* slip, int n) {
  const int i = (int)get_global_id(0);
  int me, h;
  if (i >= n) return;
  me = id ? id[i] : i;
  h = !table ? i : me >= 0 && me < table_size ? table[me] : -1;
  gr_load_pair_slips(offsets, indices, id, i, h, hist_offsets, hist_indices, hist_id, hist_slip,
                     slip);
}

/* grain i's carried collider-plane slips, looked up in the last substep's rows of planes
 * (gr_load_plane_slips): its index there from table (table_size ids; table null: the same
 * grains in the same order, its own) */
__kernel void gr_k_load_plane_slips(__global const gr_uint* offsets, __global const int* which,
                                    __global const int* id, __global const int* table,
                                    int table_size, __global const gr_uint* hist_offsets,
                                    __global const int* hist_which,
                                    __global const float* hist_normal,
                                    __global const float* hist_slip, __global float* slip, int n) {
  const int i = (int)get_global_id(0);
  int me, h;
  if (i >= n) return;
  me = id ? id[i] : i;
  h = !table ? i : me >= 0 && me < table_size ? table[me] : -1;
  gr_load_plane_slips(offsets, which, i, h, hist_offsets, hist_which, hist_normal, hist_slip,
                      slip);
}

/* a rebuild during the iterations (kernels/history.h, Iterations::carry_pairs and carry_planes):
 * what grain i's rows accumulated, carried into its rebuilt rows */
__kernel void gr_k_carry_pairs(__global const gr_uint* old_offsets,
                               __global const gr_uint* old_indices, __global const gr_uint* old_sum,
                               __global const float* old_slip, __global const gr_uint* offsets,
                               __global const gr_uint* indices, __global gr_uint* sum,
                               __global float* slip, int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  gr_carry_pair_row(old_offsets, old_indices, old_sum, old_slip, offsets, indices, sum, slip, i);
}

__kernel void gr_k_carry_planes(__global const gr_uint* old_offsets, __global const int* old_which,
                                __global const float* old_sum, __global const float* old_slip,
                                __global const gr_uint* offsets, __global const int* which,
                                __global float* sum, __global float* slip, __global float* slots,
                                int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  gr_carry_plane_row(old_offsets, old_which, old_sum, old_slip, offsets, which, sum, slip, slots,
                     i);
}

/* work-item w of `items`: the largest of v[w], v[w + items], ... into part[w] (the host takes
 * the largest of the parts: a maximum does not depend on the order it is taken in) */
__kernel void gr_k_largest(__global const float* v, int n, __global float* part) {
  const int w = (int)get_global_id(0), items = (int)get_global_size(0);
  float most = 0.0f;
  int i;
  for (i = w; i < n; i += items) most = v[i] > most ? v[i] : most;
  part[w] = most;
}

/* Chebyshev's step after an iteration (kernels/iterate.h): grain i's iterate before the last,
 * prev, becomes the next, from the iteration's result x_hat and omega */
__kernel void gr_k_chebyshev(__global const float* x_hat, __global float* prev, float omega,
                             int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  gr_store3(prev, i, gr_chebyshev(gr_load3(x_hat, i), gr_load3(prev, i), omega));
}

/* pins, once an iteration and last (kernels/pin.h): each grain moves only itself, in place */
__kernel void gr_k_pin(gr_params prm, __global const float* targetP,
                       __global const float* targetweight, __global const float* targetstiffness,
                       __global float* p, int n) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  gr_grains g = {0};
  g.targetP = targetP;
  g.targetweight = targetweight;
  g.targetstiffness = targetstiffness;
  gr_store3(p, i, gr_project_pin(&g, &prm, p, i));
}

/* contact_solver gauss_seidel's pass over one colour of blocks (gauss_seidel.cpp): work-group t
 * sweeps block blocks[first + t]'s contacts wave by wave, in place (gr_seq_pass, the CPU's
 * pass); no two blocks of a colour write one grain, nor two contacts of a wave, so the result is
 * the CPU's order's whatever the device's schedule. seq holds the contacts from number base on
 * (the host's parts) */
__kernel void gr_k_sequential(gr_params prm, GR_GRAINS_ARGS, __global float* p,
                              __global gr_seq_contact* seq, __global const gr_uint* block_wave,
                              __global const gr_uint* blocks, int first, int count, float relax,
                              gr_uint base, __global const gr_uint* wave_start) {
  gr_uint w, we, k;
  if (!gr_sweep_block(first, count, blocks, block_wave, &w, &we)) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    for (; w < we; ++w) {
      GR_WAVE(k, w, wave_start)
      gr_seq_pass(&g, &prm, p, seq + (k - base), relax);
      barrier(CLK_GLOBAL_MEM_FENCE);
    }
  }
}

/* contact_solver gauss_seidel's pre-stabilization over one colour of blocks, as gr_k_sequential
 * sweeps them (gr_seq_stabilize), writing the largest move the group made to most[block]
 * (through `part`, a float a work-item: a maximum does not depend on the order it is taken in);
 * a contact flagged in carried_flag (null: none) also adds its moves to carried */
__kernel void gr_k_stabilize(gr_params prm, GR_GRAINS_ARGS, __global float* x, __global float* p,
                             __global float* carried, __global const uchar* carried_flag,
                             __global const gr_seq_contact* seq, __global const gr_uint* block_wave,
                             __global const gr_uint* blocks, int first, int count, gr_uint base,
                             __global float* most, __global const gr_uint* wave_start,
                             __local float* part) {
  const int lid = (int)get_local_id(0), items = (int)get_local_size(0);
  gr_uint w, we, k;
  float largest = 0.0f, moved;
  int h;
  if (!gr_sweep_block(first, count, blocks, block_wave, &w, &we)) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    for (; w < we; ++w) {
      GR_WAVE(k, w, wave_start) {
        moved = gr_seq_stabilize(&g, x, p, carried_flag && carried_flag[k] ? carried : 0, seq + (k - base));
        largest = moved > largest ? moved : largest;
      }
      barrier(CLK_GLOBAL_MEM_FENCE);
    }
  }
  part[lid] = largest;
  barrier(CLK_LOCAL_MEM_FENCE);
  if (lid == 0) {
    for (h = 1; h < items; ++h) largest = part[h] > largest ? part[h] : largest;
    most[blocks[first + (int)get_group_id(0)]] = largest;
  }
}

/* gauss_seidel's contact list built on the device (Iterations::build_sequential, in this
 * order): each grain's contacts counted, the counts summed (gr_k_scan_*), each grain's written
 * from its offset (gr_seq_build: the host's build, so the same list); each block's first
 * contact; the blocks the contacts link; and, with a warm start, each contact's carried load
 * found by key in the list the device's last solve left. */
__kernel void gr_k_seq_count(gr_params prm, GR_GRAINS_ARGS, __global const int* id,
                             __global const int* plane_collider, int n, __global gr_uint* count) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    count[i] = gr_seq_build(&g, &prm, id, plane_collider, i, 0);
  }
}

__kernel void gr_k_seq_fill(gr_params prm, GR_GRAINS_ARGS, __global const int* id,
                            __global const int* plane_collider, int n,
                            __global const gr_uint* offsets, __global gr_seq_contact* seq) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  {
    const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
    gr_seq_build(&g, &prm, id, plane_collider, i, seq + offsets[i]);
  }
}

/* block b's first contact, b = 0 .. blocks (the last: the list's end) */
__kernel void gr_k_seq_blocks(__global const gr_uint* offsets, int n, int block_grains, int blocks,
                              __global gr_uint* start) {
  const int b = (int)get_global_id(0);
  if (b > blocks) return;
  start[b] = offsets[min(b * block_grains, n)];
}

/* the blocks' links (GrainsSolver::colour_blocks): a contact whose other grain moves and lies in
 * another block sets that block's bit in its own block's row of `links` (words a row, zeroed
 * before); an integer or gives the same bits in any order */
__kernel void gr_k_seq_links(__global const gr_seq_contact* seq, int count, int block_grains,
                             int words, __global volatile gr_uint* links) {
  const int k = (int)get_global_id(0);
  int bi, bj;
  if (k >= count || !(seq[k].moves & 2u)) return;
  bi = seq[k].i / block_grains;
  bj = seq[k].j / block_grains;
  if (bi != bj) atomic_or(&links[bi * words + bj / 32], 1u << (bj % 32));
}

/* the loaded contacts of the last list into `table` (2^bits slots of a contact's number + 1,
 * zeroed before), each from gr_seq_slot of its key on to the first free slot. Which slot a
 * contact takes depends on the schedule; what a lookup finds does not (keys are unique). */
__kernel void gr_k_seq_table(__global const gr_seq_contact* old, int count, int bits,
                             __global volatile gr_uint* table) {
  const int k = (int)get_global_id(0);
  const gr_uint mask = (1u << bits) - 1u;
  gr_uint h;
  if (k >= count || !(old[k].ln > 0.0f)) return;
  h = gr_seq_slot(old[k].key, bits);
  while (atomic_cmpxchg(&table[h], 0u, (gr_uint)k + 1u) != 0u) h = (h + 1u) & mask;
}

/* each contact's carried load (gauss_seidel.cpp's lookup by key): the last list's contact with
 * its key, its loads turned to the lower id's side and scaled (gr_seq_take_load); flag[k] 1 when
 * there is one */
__kernel void gr_k_seq_lookup(__global gr_seq_contact* seq, int count,
                              __global const gr_seq_contact* old, int bits,
                              __global const gr_uint* table, float scale, __global uchar* flag) {
  const int k = (int)get_global_id(0);
  const gr_uint mask = (1u << bits) - 1u;
  gr_uint h, o;
  if (k >= count) return;
  flag[k] = 0;
  for (h = gr_seq_slot(seq[k].key, bits); (o = table[h]) != 0u; h = (h + 1u) & mask) {
    __global const gr_seq_contact* c = old + (o - 1u);
    if (c->key == seq[k].key) {
      const float side = gr_seq_carry_sign(c);
      gr_seq_take_load(seq + k, c->ln,
                       gr_make3(side * c->lt[0], side * c->lt[1], side * c->lt[2]), scale);
      flag[k] = 1;
      return;
    }
  }
}

/* how many contacts carry a normal load into the next substep (an integer count) */
__kernel void gr_k_seq_loaded(__global const gr_seq_contact* seq, gr_uint base, int count,
                              __global volatile gr_uint* loaded) {
  const int k = (int)get_global_id(0);
  (void)base;
  if (k < count && seq[k].ln > 0.0f) atomic_inc(loaded);
}

/* gauss_seidel's waves on the device (Iterations::order_waves; GrainsSolver::order_waves, the
 * host's, says why): a work-item a block of one colour puts the block's contacts in waves
 * (gr_seq_wave), sorts them by wave, stably, through `copy` (each contact's flag goes with it),
 * and leaves the ends of its waves that are not empty at ends[block_start[b] + b ...], their
 * number at waves[b]. Blocks of a colour share no moving grain, so their marks never meet; each
 * block clears its own. */
__kernel void gr_k_seq_waves(__global gr_seq_contact* seq, __global gr_seq_contact* copy,
                             __global uchar* flag, __global uchar* flag_copy,
                             __global gr_ulong* mark, __global gr_uint* wave_of,
                             __global gr_uint* ends, __global const gr_uint* block_start,
                             __global const gr_uint* blocks, int first, int count,
                             __global gr_uint* waves) {
  const int t = (int)get_global_id(0);
  gr_uint b, s, e, k, w, most = 0u, beyond = 128u, last = 0u, found = 0u;
  __global gr_uint* at;
  if (t >= count) return;
  b = blocks[first + t];
  s = block_start[b];
  e = block_start[b + 1];
  for (k = s; k < e; ++k) {
    w = gr_seq_wave(mark, seq + k, &beyond);
    wave_of[k] = w;
    most = w + 1u > most ? w + 1u : most;
  }
  /* a block's waves number at most its contacts: most + 1 counts fit from s + b */
  at = ends + s + b;
  for (w = 0u; w <= most; ++w) at[w] = 0u;
  for (k = s; k < e; ++k) ++at[wave_of[k] + 1u];
  for (w = 0u; w < most; ++w) at[w + 1u] += at[w];
  for (k = s; k < e; ++k) {
    const gr_uint to = s + at[wave_of[k]]++;
    copy[to] = seq[k];
    if (flag) flag_copy[to] = flag[k];
  }
  for (k = s; k < e; ++k) {
    seq[k] = copy[k];
    if (flag) flag[k] = flag_copy[k];
    if (seq[k].moves & 1u) mark[2 * (gr_ulong)seq[k].i] = mark[2 * (gr_ulong)seq[k].i + 1] = 0;
    if (seq[k].moves & 2u) mark[2 * (gr_ulong)seq[k].j] = mark[2 * (gr_ulong)seq[k].j + 1] = 0;
  }
  /* at[w] is now where wave w ends (relative to s): the ends of the waves that are not empty */
  for (w = 0u; w < most; ++w)
    if (at[w] != last) last = at[w], at[found++] = last;
  waves[b] = found;
}

/* each wave's first contact, block by block (block_wave: each block's first wave, from the
 * host): a block's first wave starts at its first contact, each other where the one before ends
 * (gr_k_seq_waves' ends); the list's end, the last entry, the host writes */
__kernel void gr_k_seq_wave_starts(__global const gr_uint* ends, __global const gr_uint* block_start,
                                   __global const gr_uint* block_wave, int blocks,
                                   __global gr_uint* wave_start) {
  const int b = (int)get_global_id(0);
  gr_uint s, w0, t, n;
  if (b >= blocks) return;
  s = block_start[b];
  w0 = block_wave[b];
  n = block_wave[b + 1] - w0;
  for (t = 0u; t < n; ++t) wave_start[w0 + t] = s + (t ? ends[s + (gr_uint)b + t - 1u] : 0u);
}

/* The neighbour rows on the device (kernels/grid.h; opencl/neighbours.cpp launches these in
 * order): the bounds, the grains counted and placed in their cells, the rows counted, then
 * filled. Integer atomics only count: a cell's grains may sit in any order, and a row, sorted by
 * unique keys, does not depend on it. Double precision is the pair test's (engine/pair_test.h);
 * a device without it builds the rows on the host. */
#ifdef GR_DOUBLES
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#include "grid.h"

/* A mesh collider's queries (engine/mesh_query.h, in double precision): the hooks
 * engine/collider_shape.h declares, on the mesh's arrays here (gr_mesh_of). */
#define GR_MESH_QUERIES
#include "mesh_query.h"

float gr_mesh_distance(const gr_mesh* mesh, const float* p, float* n, float within) {
  return gr_mesh_query_distance(mesh, p, n, within);
}

float gr_mesh_crossing(const gr_mesh* mesh, const float* a, const float* b, float* n) {
  return gr_mesh_query_crossing(mesh, a, b, n);
}

int gr_mesh_shell(const gr_mesh* mesh) {
  return !mesh->closed;
}

/* work-item w of `items`: the smallest and largest finite coordinates and the largest radius of
 * grains w, w + items, ... into part[7 w ...] (lo xyz, hi xyz, r): the host takes the extremes,
 * which do not depend on the order they are met in */
__kernel void gr_k_bounds(__global const float* P, __global const float* radius, int n,
                          __global float* part) {
  const int w = (int)get_global_id(0), items = (int)get_global_size(0);
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  float r = -INFINITY;
  int i, a;
  for (i = w; i < n; i += items) {
    for (a = 0; a < 3; ++a) {
      const float v = P[3 * i + a];
      if (isfinite(v)) {
        lo[a] = v < lo[a] ? v : lo[a];
        hi[a] = v > hi[a] ? v : hi[a];
      }
    }
    r = radius[i] > r ? radius[i] : r;
  }
  for (a = 0; a < 3; ++a) part[7 * w + a] = lo[a], part[7 * w + 3 + a] = hi[a];
  part[7 * w + 6] = r;
}

/* each grain's cell slot, and the cells' counts (zeroed before) */
__kernel void gr_k_cell_count(gr_grid grid, __global const float* P, int n, __global gr_uint* key,
                              __global volatile gr_uint* count) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  key[i] = gr_grid_key_of(&grid, P, i);
  atomic_inc(&count[key[i]]);
}

/* each grain into its cell: grains[start[key] ...] in arrival order (cursor zeroed before),
 * its position and radius at sorted[4 slot ...] */
__kernel void gr_k_cell_place(__global const gr_uint* key, int n, __global const gr_uint* start,
                              __global volatile gr_uint* cursor, __global gr_uint* grains,
                              __global const float* P, __global const float* radius,
                              __global float* sorted) {
  const int i = (int)get_global_id(0);
  gr_uint s;
  if (i >= n) return;
  s = start[key[i]] + atomic_inc(&cursor[key[i]]);
  grains[s] = (gr_uint)i;
  vstore4((float4)(P[3 * i], P[3 * i + 1], P[3 * i + 2], radius[i]), s, sorted);
}

/* each grain's row length (gr_grid_row_count) */
__kernel void gr_k_row_count(gr_grid grid, __global const float* P, __global const float* radius,
                             __global const gr_uint* start, __global const gr_uint* grains,
                             __global const float* sorted, int n, __global gr_uint* length) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  length[i] = gr_grid_row_count(&grid, P, radius, start, grains, sorted, i);
}

/* each grain's row (gr_grid_row_fill) at offsets[i], keys its scratch */
__kernel void gr_k_row_fill(gr_grid grid, __global const float* P, __global const float* radius,
                            __global const gr_uint* start, __global const gr_uint* grains,
                            __global const float* sorted, int n, __global const gr_uint* offsets,
                            __global gr_pair_key_t* keys, __global gr_uint* indices) {
  const int i = (int)get_global_id(0);
  if (i >= n) return;
  gr_grid_row_fill(&grid, P, radius, start, grains, sorted, i, offsets[i], offsets[i + 1], keys,
                   indices);
}

/* What the host reads along the rows (kernels/row_stats.h), run w of `runs` (grains
 * [n w / runs, n (w + 1) / runs)) a work-item; the host combines the runs in order.
 * gr_k_row_overlaps: touching pairs, the largest overlap and the overlaps' sum at part[3 w ...];
 * gr_k_row_reach: the full rows' smallest reach at part[w] (+infinity: none);
 * gr_k_row_longest: the most entries a row holds at part[w];
 * gr_k_rows_moved: the largest squared move from b, the rows' positions, to p at part[w] */
#include "motion_need.h"
#include "row_stats.h"
#include "sleep.h"

__kernel void gr_k_row_overlaps(__global const float* P, __global const float* radius,
                                __global const gr_uint* offsets, __global const gr_uint* indices,
                                int n, int runs, __global double* part) {
  const int w = (int)get_global_id(0);
  double contacts = 0.0, sum = 0.0;
  float largest = 0.0f;
  if (w >= runs) return;
  gr_row_overlaps(P, radius, offsets, indices, (int)((long)n * w / runs),
                  (int)((long)n * (w + 1) / runs), &contacts, &largest, &sum);
  part[3 * w] = contacts;
  part[3 * w + 1] = (double)largest;
  part[3 * w + 2] = sum;
}

__kernel void gr_k_row_reach(__global const float* p, __global const float* radius,
                             __global const gr_uint* offsets, __global const gr_uint* indices,
                             int n, int runs, gr_uint full, float r_max, __global float* part) {
  const int w = (int)get_global_id(0);
  float reach = INFINITY;
  if (w >= runs) return;
  gr_row_reach(p, radius, offsets, indices, (int)((long)n * w / runs),
               (int)((long)n * (w + 1) / runs), full, r_max, &reach);
  part[w] = reach;
}

__kernel void gr_k_row_longest(__global const gr_uint* offsets, int n, int runs,
                               __global gr_uint* part) {
  const int w = (int)get_global_id(0);
  gr_uint longest = 0u;
  if (w >= runs) return;
  gr_row_longest(offsets, (int)((long)n * w / runs), (int)((long)n * (w + 1) / runs), &longest);
  part[w] = longest;
}

__kernel void gr_k_rows_moved(__global const float* p, __global const float* b, int n, int runs,
                              __global float* part) {
  const int w = (int)get_global_id(0);
  float moved2 = 0.0f;
  if (w >= runs) return;
  gr_rows_moved(p, b, (int)((long)n * w / runs), (int)((long)n * (w + 1) / runs), &moved2);
  part[w] = moved2;
}

/* gr_k_sleep_rows: each grain's sleeping reads along its row (gr_row_sleep), a work-item a
 * grain */
__kernel void gr_k_sleep_rows(__global const float* P, __global const float* radius,
                              __global const gr_uint* offsets, __global const gr_uint* indices,
                              __global const uchar* fast, int n, __global gr_uint* out) {
  const int k = (int)get_global_id(0);
  if (k >= n) return;
  out[k] = gr_row_sleep(P, radius, offsets, indices, fast, k);
}

/* gr_k_motion: error control's motion measure (engine/motion_need.h) over the grains w, w +
 * items, ... of the end held there (v) with their forces (one row for all where force_uniform;
 * none: null), masses and radii: part[2 w] the substeps a frame their motion needs (at least
 * 1), part[2 w + 1] the largest acceleration / radius; the host takes the largest of each */
__kernel void gr_k_motion(__global const float* v, __global const float* force, int force_uniform,
                          __global const float* mass, __global const float* radius, double step,
                          double fps, int n, int items, __global double* part) {
  const int w = (int)get_global_id(0);
  double worst = 1.0, fall = 0.0;
  int k;
  if (w >= items) return;
  for (k = w; k < n; k += items) {
    const int f = force_uniform ? 0 : k;
    const float acc =
        force ? gr_motion_acc(force[3 * f], force[3 * f + 1], force[3 * f + 2], mass[k]) : 0.0f;
    gr_motion_need(v[3 * k], v[3 * k + 1], v[3 * k + 2], acc, radius[k], step, fps, &worst, &fall);
  }
  part[2 * w] = worst;
  part[2 * w + 1] = fall;
}

/* The sleeping test on the device (kernels/sleep.h; opencl/sleep.cpp), a work-item a grain. */
GR_INLINE gr_sleep gr_device_sleep(__global float* time, __global float* anchor,
                                   __global float* accel, __global int* contacts,
                                   __global const uchar* can, __global const float* mass,
                                   __global const float* radius, __global const float* force,
                                   int force_uniform, __global const float* start,
                                   __global const float* start_v, __global uchar* asleep,
                                   __global uchar* woken, __global uchar* fast) {
  gr_sleep s;
  s.time = time;
  s.anchor = anchor;
  s.accel = accel;
  s.contacts = contacts;
  s.can = can;
  s.mass = mass;
  s.radius = radius;
  s.force = force;
  s.force_index = 0;
  s.force_uniform = force_uniform;
  s.start = start;
  s.start_v = start_v;
  s.asleep = asleep;
  s.woken = woken;
  s.fast = fast;
  return s;
}

/* gr_k_sleep_begin: before the substep (gr_sleep_begin), from the start P (world; grain k's
 * at row from[k] where `from` is set) and the velocities v: the start and the start velocity
 * kept (start, start_v), the mass awake (`awake`), and a sleeper made a fixed grain (mass,
 * inverse mass and velocity 0). `changed` is set where a grain sleeps this substep and did not
 * the last, or the reverse (`prev`: the last substep's are in asleep) */
__kernel void gr_k_sleep_begin(gr_sleep_params sp, __global const float* P, __global float* start,
                               __global float* v, __global float* start_v, __global float* mass,
                               __global float* awake, __global float* inv_mass,
                               __global const float* radius, __global const uchar* can,
                               __global const float* force, int force_uniform,
                               __global float* time, __global float* anchor,
                               __global float* accel, __global uchar* asleep, int prev,
                               __global int* changed, int n, __global const gr_uint* from) {
  const int k = (int)get_global_id(0);
  gr_sleep s;
  gr_float3 p;
  int sleeps;
  if (k >= n) return;
  p = gr_load3(P, from ? (int)from[k] : k);
  gr_store3(start, k, p);
  gr_store3(start_v, k, gr_load3(v, k));
  awake[k] = mass[k];
  s = gr_device_sleep(time, anchor, accel, 0, can, awake, radius, force, force_uniform, start,
                      start_v, asleep, 0, 0);
  sleeps = gr_sleep_begin(&sp, &s, k, p);
  if (!prev || sleeps != (int)asleep[k]) *changed = 1;
  asleep[k] = (uchar)sleeps;
  if (!sleeps) return;
  mass[k] = 0.0f;
  inv_mass[k] = 0.0f;
  gr_store3(v, k, (float3)(0.0f));
}

/* gr_k_sleep_settle: after the substep, at its end P and v (world; gr_sleep_settle) */
__kernel void gr_k_sleep_settle(gr_sleep_params sp, __global float* P, __global float* v,
                                __global const float* start, __global const float* start_v,
                                __global const float* awake, __global const float* radius,
                                __global const float* force, int force_uniform,
                                __global uchar* asleep, __global uchar* woken,
                                __global uchar* fast, int n) {
  const int k = (int)get_global_id(0);
  gr_sleep s;
  if (k >= n) return;
  s = gr_device_sleep(0, 0, 0, 0, 0, awake, radius, force, force_uniform, start, start_v, asleep,
                      woken, fast);
  gr_sleep_settle(&sp, &s, k, P, v);
}

/* gr_k_sleep_carry: the sleeping test's state of n grains in a new order, grain k's from row
 * from[k] of the state the last substep left (time, anchor, accel, contacts into the to_
 * arrays) */
__kernel void gr_k_sleep_carry(__global const gr_uint* from, __global const float* time,
                               __global const float* anchor, __global const float* accel,
                               __global const int* contacts, __global float* to_time,
                               __global float* to_anchor, __global float* to_accel,
                               __global int* to_contacts, int n) {
  const int k = (int)get_global_id(0);
  int j;
  if (k >= n) return;
  j = (int)from[k];
  to_time[k] = time[j];
  gr_store3(to_anchor, k, gr_load3(anchor, j));
  gr_store3(to_accel, k, gr_load3(accel, j));
  to_contacts[k] = contacts[j];
}

/* gr_k_sleep_update: the sleepers the colliders that moved wake (gr_sleep_collider_near; the
 * still ones are skipped), those the rows wake (gr_sleep_rows_wake, no rows: none), then each grain's stay
 * (gr_sleep_stay), its contacts noted where it falls asleep */
__kernel void gr_k_sleep_update(gr_sleep_params sp, __global const float* P, __global float* v,
                                __global const float* radius, __global const gr_uint* offsets,
                                __global const gr_uint* indices, __global const float* awake,
                                __global const uchar* can, __global const float* force,
                                int force_uniform, __global float* time, __global float* anchor,
                                __global float* accel, __global int* contacts,
                                __global uchar* asleep, __global uchar* woken,
                                __global const uchar* fast, int n,
                                __global const gr_collider* colliders, int collider_count,
                                __global const int* meshes) {
  const int k = (int)get_global_id(0);
  gr_sleep s;
  int c;
  if (k >= n) return;
  s = gr_device_sleep(time, anchor, accel, contacts, can, awake, radius, force, force_uniform, 0,
                      0, asleep, woken, 0);
  for (c = 0; c < collider_count && asleep[k] && !woken[k]; ++c) {
    const gr_collider col = colliders[c];
    GR_MESH_OF_COLLIDER(mesh, c);
    if (!gr_collider_still(&col) && gr_sleep_collider_near(&sp, &s, k, &col, P, mesh)) woken[k] = 1;
  }
  if (offsets && asleep[k] && !woken[k])
    gr_sleep_rows_wake(&s, k, (int)gr_row_near(P, radius, offsets, indices, k, GR_SLEEP_KEPT),
                       gr_row_fast_near(P, radius, offsets, indices, fast, k, GR_SLEEP_NEAR));
  if (gr_sleep_stay(&sp, &s, k, P, v))
    contacts[k] = offsets ? (int)gr_row_near(P, radius, offsets, indices, k, GR_SLEEP_NEAR) : 0;
}
#include "shapes.h"

/* rigid shape matching (kernels/shapes.h, in double precision), a work-group of GR_SHAPE_LANES
 * work-items a component (its lanes), in place after a pass and before the pins: each
 * component's fit, shift out of its collider planes and friction with them, the stages and folds
 * of shapes.cpp in its order, a barrier between them (a component's members are its own) */
#define GR_SHAPE_SYNC barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE)
__kernel __attribute__((reqd_work_group_size(GR_SHAPE_LANES, 1, 1))) void gr_k_shapes(
    gr_params prm, GR_GRAINS_ARGS, __global float* p, __global const gr_uint* offsets,
    __global const gr_uint* members, __global const float* rest, __global const float* shape_mass,
    __global float* collider_normal, int components) {
  __local double parts[GR_SHAPE_LANES * GR_SHAPE_ROW];
  __local double rot[9], motion[6];
  const gr_uint c = (gr_uint)get_group_id(0);
  const int l = (int)get_local_id(0);
  const gr_grains g = gr_device_grains(GR_GRAINS_NAMES);
  double means[6], centre[3];
  gr_shapes s;
  int lanes;
  if ((int)c >= components) return; /* the whole group */
  s.offsets = offsets;
  s.members = members;
  s.rest = rest;
  s.mass = shape_mass;
  s.collider_normal = collider_normal;
  lanes = gr_shape_lanes(&s, c); /* the folds read these lanes' rows */
  gr_shape_mass_lane(&s, p, c, l, parts);
  GR_SHAPE_SYNC;
  if (l == 0) gr_shape_fold_sum(parts, 7, lanes);
  GR_SHAPE_SYNC;
  gr_shape_means(parts, means);
  GR_SHAPE_SYNC;
  gr_shape_fit_lane(&s, p, c, l, means, parts);
  GR_SHAPE_SYNC;
  if (l == 0) gr_shape_fold_sum(parts, 9, lanes);
  GR_SHAPE_SYNC;
  if (l == 0) gr_shape_fit_rotation(parts, rot);
  GR_SHAPE_SYNC;
  gr_shape_goal_lane(&s, p, c, l, means, rot);
  if (!g.plane_offsets) return;
  GR_SHAPE_SYNC;
  gr_shape_shift_lane(&s, &g, &prm, p, c, l, parts);
  GR_SHAPE_SYNC;
  if (l == 0) gr_shape_fold_bounds(parts, lanes);
  GR_SHAPE_SYNC;
  gr_shape_shift_apply(&s, p, c, l, parts);
  if (!collider_normal || !(prm.friction_with_colliders > 0.0f)) return;
  GR_SHAPE_SYNC;
  gr_shape_body_lane(&s, &g, p, c, l, parts);
  GR_SHAPE_SYNC;
  if (l == 0) gr_shape_fold_sum(parts, 5, lanes);
  GR_SHAPE_SYNC;
  if (!(parts[4] > 0.0)) return; /* no contact touching: the whole group */
  {
    const double mass = parts[3];
    gr_shape_centre(parts, centre);
    GR_SHAPE_SYNC;
    gr_shape_inertia_lane(&s, p, c, l, centre, parts);
    GR_SHAPE_SYNC;
    if (l == 0) gr_shape_fold_sum(parts, 9, lanes);
    GR_SHAPE_SYNC;
    if (l == 0) {
      double out[6];
      int r;
      gr_shape_friction(&s, &g, &prm, p, c, centre, mass, parts, out);
      for (r = 0; r < 6; ++r) motion[r] = out[r];
    }
    GR_SHAPE_SYNC;
    gr_shape_friction_apply(&s, p, c, l, centre, motion);
  }
}
#else
/* no double precision: the host makes every mesh's queries (Iterations::meshes_there), and
 * these are never reached */
float gr_mesh_distance(const gr_mesh* mesh, const float* p, float* n, float within) {
  (void)mesh, (void)p, (void)within;
  if (n) n[0] = 0.0f, n[1] = 1.0f, n[2] = 0.0f;
  return 1e30f;
}

float gr_mesh_crossing(const gr_mesh* mesh, const float* a, const float* b, float* n) {
  (void)mesh, (void)a, (void)b, (void)n;
  return 2.0f;
}

int gr_mesh_shell(const gr_mesh* mesh) {
  (void)mesh;
  return 0;
}
#endif

/* An exclusive prefix sum of n counts, in place, with the total at [n]: gr_k_scan_blocks sums
 * each block of `block` counts (a work-item a block), gr_k_scan_sums turns those sums into the
 * blocks' starts (one work-item), gr_k_scan_apply writes each block's running sums from its
 * start. Integer sums: the same whatever the schedule. */
__kernel void gr_k_scan_blocks(__global const gr_uint* x, int n, int block, __global gr_uint* sums,
                               int blocks) {
  const int b = (int)get_global_id(0);
  int k, end;
  gr_uint total = 0;
  if (b >= blocks) return;
  end = min(n, (b + 1) * block);
  for (k = b * block; k < end; ++k) total += x[k];
  sums[b] = total;
}

__kernel void gr_k_scan_sums(__global gr_uint* sums, int blocks) {
  gr_uint total = 0, v;
  int b;
  if (get_global_id(0) != 0) return;
  for (b = 0; b < blocks; ++b) v = sums[b], sums[b] = total, total += v;
  sums[blocks] = total;
}

__kernel void gr_k_scan_apply(__global gr_uint* x, int n, int block, __global const gr_uint* sums,
                              int blocks) {
  const int b = (int)get_global_id(0);
  int k, end;
  gr_uint total, v;
  if (b >= blocks) return;
  total = sums[b];
  end = min(n, (b + 1) * block);
  for (k = b * block; k < end; ++k) v = x[k], x[k] = total, total += v;
  if (b == blocks - 1) x[n] = sums[blocks];
}

/* The collider planes (kernels/planes.h): a work-item a grain, gr_k_plane_count counts its
 * planes into count[i] (the host's scan turns the counts into offsets), gr_k_plane_fill writes
 * them from offsets[i] on: the surface point, normal and the collider's velocity there (9
 * floats an entry) and the collider. A grain's row is the CPU's, bit for bit (no contraction,
 * engine/collider_shape.h). */
#define GR_PLANE_ARGS                                                                        \
  __global const gr_collider *colliders, int count, float ox, float oy, float oz,            \
      float query_scale, __global const float *P, __global const float *p,                   \
      __global const float *radius, __global const float *inv_mass, int n,                  \
      __global const int *meshes

/* grain i's planes into dist, nrm, idx, and p's copy into pi; returns how many */
GR_INLINE int gr_device_planes(__global const gr_collider* colliders, int count, float ox,
                               float oy, float oz, float query_scale, __global const float* P,
                               __global const float* p, __global const float* radius,
                               __global const float* inv_mass, __global const int* meshes, int i,
                               float* pi, float* dist, float* nrm, int* idx) {
  const float origin[3] = {ox, oy, oz};
  const float Pi[3] = {P[3 * i], P[3 * i + 1], P[3 * i + 2]};
  pi[0] = p[3 * i], pi[1] = p[3 * i + 1], pi[2] = p[3 * i + 2];
  return gr_plane_nearest(colliders, count, origin, query_scale, radius[i], inv_mass[i], pi, Pi,
                          dist, nrm, idx, meshes);
}

__kernel void gr_k_plane_count(GR_PLANE_ARGS, __global gr_uint* counts) {
  const int i = (int)get_global_id(0);
  float pi[3], dist[GR_MAX_PLANES], nrm[3 * GR_MAX_PLANES];
  int idx[GR_MAX_PLANES];
  if (i >= n) return;
  counts[i] = (gr_uint)gr_device_planes(colliders, count, ox, oy, oz, query_scale, P, p, radius,
                                        inv_mass, meshes, i, pi, dist, nrm, idx);
}

__kernel void gr_k_plane_fill(GR_PLANE_ARGS, __global const gr_uint* offsets, __global float* plane,
                              __global int* which) {
  const int i = (int)get_global_id(0);
  const float origin[3] = {ox, oy, oz};
  float pi[3], dist[GR_MAX_PLANES], nrm[3 * GR_MAX_PLANES];
  int idx[GR_MAX_PLANES], found, k, a;
  if (i >= n || offsets[i + 1] == offsets[i]) return;
  found = gr_device_planes(colliders, count, ox, oy, oz, query_scale, P, p, radius, inv_mass,
                           meshes, i, pi, dist, nrm, idx);
  for (k = 0; k < found; ++k) {
    const gr_uint e = offsets[i] + (gr_uint)k;
    const gr_collider col = colliders[idx[k]];
    float xs[3], world[3], v[3];
    gr_plane_surface(pi, nrm + 3 * k, dist[k], origin, xs, world);
    gr_collider_velocity(&col, world, v);
    for (a = 0; a < 3; ++a) {
      plane[9 * e + a] = xs[a];
      plane[9 * e + 3 + a] = nrm[3 * k + a];
      plane[9 * e + 6 + a] = v[a];
    }
    which[e] = idx[k];
  }
}

/* Whether the planes gr_k_plane_fill left (offsets, n + 1, and which) are the ones a list was
 * built from (kept_offsets, kept_which: Iterations::keep_planes), of the same number of entries:
 * a work-item a grain compares its row's end and colliders and sets *differs (an integer, so
 * the answer is the same whichever item sets it). */
__kernel void gr_k_plane_same(__global const gr_uint* offsets, __global const int* which,
                              __global const gr_uint* kept_offsets,
                              __global const int* kept_which, int n, __global int* differs) {
  const int i = (int)get_global_id(0);
  gr_uint e;
  if (i >= n) return;
  if (offsets[i + 1] != kept_offsets[i + 1]) {
    atomic_or(differs, 1);
    return;
  }
  for (e = offsets[i]; e < offsets[i + 1]; ++e)
    if (which[e] != kept_which[e]) {
      atomic_or(differs, 1);
      return;
    }
}
