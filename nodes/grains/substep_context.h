// The substep's shared state, private to the solver's sources (solver.cpp, gauss_seidel.cpp).
#pragma once
#include "nodes/grains/kernels/iterate.h"
#include "nodes/grains/solver.h"

namespace grains {

// The substep's inputs and switches its stages share (substep() fills it; n is n_)
struct GrainsSolver::SubstepContext {
  SubstepContext(GrainsData& data, const GrainsSettings& settings, const ColliderState* cs,
                 size_t count, gr_grains& grains, gr_params& params, gr_normal_sums& sums)
      : d(data), s(settings), colliders(cs), collider_count(count), g(grains), prm(params),
        acc(sums) {}
  GrainsData& d;
  const GrainsSettings& s;
  const ColliderState* colliders;
  size_t collider_count;
  gr_grains& g;
  gr_params& prm;
  gr_normal_sums& acc;
  Vec3 origin{};
  int threads = 1;
  int iterations = 0;
  bool pairs_on = false, colliders_on = false, constraints_on = false, shapes_on = false;
  // rigid shapes projected here between a device's passes (jacobi's, or a device without double
  // precision), not on the device after each of gauss_seidel's (SequentialContacts::shapes)
  bool shapes_here = false;
  bool pair_friction_pass = false, collider_friction_pass = false, impacts = false;
  // the impact data made here, from the host's contacts or sums and its end of the substep (else
  // gauss_seidel's device makes them at its end, gr_k_final_collision: open_sums says where)
  bool impacts_here = false;
  bool reusable = false;   // the neighbour rows may be kept across substeps (keep_rows)
  bool same_rows = false;  // they were: this substep's rows are the last one's
  const float* search_radius = nullptr;
  NeighborQuery q;
  // use_opencl (gauss_seidel, or jacobi_there): g's force as the device reads it (device_force),
  // made once a substep for the prediction and the end there
  const float* device_force = nullptr;
  bool force_uniform = false;
  // use_opencl with jacobi: the prediction, pre-stabilization, iterations and end chained on the
  // device (GrainsSolver::jacobi_on_device)
  bool jacobi_there = false;
  // ... and the rows and planes found again during the iterations there, within the one call
  // (GrainsSolver::rebuilds_there)
  bool rebuilds_there = false;
};

// The final collision test of one grain moving from a to b (world) with velocity v, radius r and
// collider friction mu (friction_with_colliders x its friction), against the colliders in order
// (kernels/final_collision.h; meshes[c]: collider c's mesh, null for an analytic shape): moves b
// and v, and returns the last collider that acted, with its normal in *hit_n, or -1 when none did
// (final_collision.cpp).
int32_t final_collision(const gr_collider* colliders, const void* const* meshes, size_t count,
                        const Vec3& a, Vec3& b, Vec3& v, float r, float mu, const gr_params& prm,
                        Vec3* hit_n);

// Impact data (kernels/impact.h, through impact.cpp): gauss_seidel's `count` contacts' loads into
// their grains' slots of dx (3 GR_MAX_PLANES floats a grain, zero before) ...
void impact_loads(const gr_grains& g, const gr_seq_contact* seq, size_t count, float* dx);
// ... and grain i's slots of d's impact data at the substep's end (gr_impact_slots: b, v its
// end, v_loop its velocity before the final collision test, hit the last collider the test
// acted on along hit_n, -1: none)
void impact_slots(const gr_grains& g, float dt, size_t i, const float* dx,
                  const int32_t* plane_collider, const Vec3& b, const Vec3& v, const Vec3& v_loop,
                  int32_t hit, const Vec3& hit_n, GrainsData& d);

}  // namespace grains
