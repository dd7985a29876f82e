// Rigid shape matching on the host (kernels/shapes.h), a component at a time, for
// GrainsSolver::project_shapes: the stages of gr_k_shapes (grains.cl), the lanes a component uses
// run one after another. This file is compiled without a multiply and an add fused
// (CMakeLists.txt), as an OpenCL device runs the shared functions: the same floats, bit for bit.
#include "nodes/grains/shapes.h"

namespace grains {

namespace {

void project(const gr_shapes& s, const gr_grains& g, const gr_params& prm, float* p, gr_uint c) {
  double parts[GR_SHAPE_LANES * GR_SHAPE_ROW];
  double means[6];
  const int lanes = gr_shape_lanes(&s, c);  // a two-grain body runs two, not 64
  gr_shape_mass_lane(&s, p, c, 0, parts);     // a component has two grains or more
  for (int l = 1; l < lanes; ++l) gr_shape_mass_lane(&s, p, c, l, parts);
  gr_shape_fold_sum(parts, 7, lanes);
  gr_shape_means(parts, means);
  for (int l = 0; l < lanes; ++l) gr_shape_fit_lane(&s, p, c, l, means, parts);
  gr_shape_fold_sum(parts, 9, lanes);
  double rot[9];
  gr_shape_fit_rotation(parts, rot);
  for (int l = 0; l < lanes; ++l) gr_shape_goal_lane(&s, p, c, l, means, rot);
  if (!g.plane_offsets) return;
  for (int l = 0; l < lanes; ++l) gr_shape_shift_lane(&s, &g, &prm, p, c, l, parts);
  gr_shape_fold_bounds(parts, lanes);
  for (int l = 0; l < lanes; ++l) gr_shape_shift_apply(&s, p, c, l, parts);
  if (!s.collider_normal || !(prm.friction_with_colliders > 0.0f)) return;
  for (int l = 0; l < lanes; ++l) gr_shape_body_lane(&s, &g, p, c, l, parts);
  gr_shape_fold_sum(parts, 5, lanes);
  if (!(parts[4] > 0.0)) return;  // no contact touching
  const double mass = parts[3];
  double centre[3];
  gr_shape_centre(parts, centre);
  for (int l = 0; l < lanes; ++l) gr_shape_inertia_lane(&s, p, c, l, centre, parts);
  gr_shape_fold_sum(parts, 9, lanes);
  double motion[6];
  gr_shape_friction(&s, &g, &prm, p, c, centre, mass, parts, motion);
  for (int l = 0; l < lanes; ++l) gr_shape_friction_apply(&s, p, c, l, centre, motion);
}

}  // namespace

void project_components(const gr_shapes& s, const gr_grains& g, const gr_params& prm, float* p,
                        size_t components, int threads) {
  const long comps = static_cast<long>(components);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (long c = 0; c < comps; ++c) project(s, g, prm, p, static_cast<gr_uint>(c));
}

}  // namespace grains
