/* The grains kernels as one OpenCL C 1.2 program: every shared header (nodes/grains/kernels/,
 * the same code the CPU path compiles) and, so far, one kernel that calls the per-grain steps of
 * a substep (predict, the iteration, pre-stabilization, the friction pass, the velocity update).
 * `grains devices` builds this program on each device it lists, and the ctest
 * opencl_kernels_compile compiles it to SPIR with clang, so that code generation, not only
 * parsing, sees the code the CPU path runs. The substep does not run on a device yet. */
#include "clumping.h"
#include "collider.h"
#include "contact.h"
#include "distance.h"
#include "iterate.h"
#include "mass_shock.h"
#include "params.h"
#include "pin.h"
#include "velocity.h"

__kernel void gr_probe_substep(gr_params prm, __global const float* P, __global const float* v,
                               __global float* p, __global float* out) {
  const int i = (int)get_global_id(0);
  gr_grains g = {0};
  g.P = P;
  g.v = v;
  gr_normal_sums acc = {0};
  gr_predict(&g, &prm, p, i);
  gr_float3 y = gr_iterate(&g, &prm, p, i, &acc);
  y = gr_add(y, gr_stabilize(&g, &prm, p, i));
  y = gr_add(y, gr_friction_pass(&g, &prm, p, &acc, i));
  gr_float3 Pk, vk;
  gr_update_velocity(&g, &prm, p, i, &Pk, &vk);
  gr_store3(out, i, gr_add(y, gr_add(Pk, vk)));
}
