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
  bool pair_friction_pass = false, collider_friction_pass = false, impacts = false;
  bool reusable = false;   // the neighbour rows may be kept across substeps (keep_rows)
  bool same_rows = false;  // they were: this substep's rows are the last one's
  const float* search_radius = nullptr;
  NeighborQuery q;
};

}  // namespace grains
