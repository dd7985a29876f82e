// Rigid shape matching on the host (kernels/shapes.h; shapes.cpp), made as a device makes it
// (gr_k_shapes), bit for bit.
#pragma once
#include <cstddef>

#include "nodes/grains/kernels/shapes.h"

namespace grains {

// Each of s's `components` components projected on p (3 n floats, in place): fitted, shifted out
// of g's collider planes (none where g.plane_offsets is null) and, with s.collider_normal and
// collider friction, its slip along them taken out as a rigid body (g.P: the start it is measured
// from), over `threads` threads: the same floats whatever their number
void project_components(const gr_shapes& s, const gr_grains& g, const gr_params& prm, float* p,
                        size_t components, int threads);

}  // namespace grains
