// Measures of a deposit with the DEM reference's definitions (../shared/reference/dem/metrics.py),
// y up (the DEM's z), so Grains runs compare with the LIGGGHTS results figure for figure.
//
// The angle of a heap, measured as the DEM reference does (../shared/reference/dem/metrics.py,
// `pile`): around the vertical axis through (cx, cz), in `sectors` azimuthal sectors, the surface
// height in rings one grain diameter d wide is the highest grain top (y + pscale) of the moving
// grains (mass > 0; fixed grains are the bed). A sector's foot is its first ring beyond 2 d whose
// top is below 1.5 d; a line fitted to the rings inside the foot whose top lies between 20% and
// 80% of the peak height gives the sector's angle atan(-slope). angle_deg is the mean over
// sectors with at least 3 such rings (0 when none has: a flat layer, no heap), spread_deg their
// standard deviation; cone_deg = atan(peak / mean foot radius).
#pragma once
#include <vector>

#include "engine/particles.h"

namespace grains {

// Mean and sample standard deviation (0 for fewer than two values) of the sectors' angles.
struct MeanSd {
  double mean = 0, sd = 0;
};
MeanSd mean_sd(const std::vector<double>& values);

struct HeapAngle {
  double angle_deg = 0, spread_deg = 0, cone_deg = 0;
  double peak = 0;         // m, highest grain top
  double foot_radius = 0;  // m, mean over sectors
  int sectors = 0;         // sectors with a flank
  size_t grains = 0;       // moving grains measured
};

HeapAngle heap_angle(const ParticleStore& pts, double d, double cx = 0, double cz = 0,
                     int sectors = 8);

// A planar column collapse against a back wall at x = 0 (metrics.py `collapse`): L0 and H0 the
// initial column's length (largest x + pscale) and height (largest y + pscale); the deposit ends
// at the first slice of width d along x, from the wall, that holds fewer grains than half a
// monolayer (0.5 W / d, W the channel's width along z: the grains' z extent + d). runout =
// (L - L0) / L0, height = the highest grain top H / L0.
struct CollapseMetric {
  double L0 = 0, H0 = 0, L = 0, H = 0;
  double runout = 0, height = 0;  // (L - L0) / L0, H / L0
  size_t beyond = 0;              // grains past the front
};
CollapseMetric collapse_metric(const ParticleStore& initial, const ParticleStore& final_state,
                               double d);

}  // namespace grains
