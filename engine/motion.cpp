#include "engine/motion.h"

#include <algorithm>
#include <cmath>

#include "engine/motion_need.h"

namespace grains {

bool motion_need(const ParticleStore& pts, double fps, const MotionBounds& bounds, double* worst,
                 double* fall) {
  const float* v = pts.v3_if("v");  // positions are not read (they may stay held: particles.h)
  const float* F = pts.v3_if("force");
  const float* m = pts.f_if("mass");
  const float* r = pts.f_if("pscale");
  const int32_t* pbd = pts.i_if("ispbd");
  if (!pts.has("P") || !v || !r || !pbd) return false;
  for (size_t k = 0; k < pts.size(); ++k) {
    if (!pbd[k]) continue;
    const float acc = F && m ? gr_motion_acc(F[3 * k], F[3 * k + 1], F[3 * k + 2], m[k]) : 0.0f;
    gr_motion_need(v[3 * k], v[3 * k + 1], v[3 * k + 2], acc, r[k], bounds.step, fps, worst, fall);
  }
  return true;
}

int motion_substeps(const ParticleStore& pts, double fps, int most, const MotionBounds& bounds,
                    Node* holder) {
  double worst = 1;
  double fall = 0;  // the largest acc / r
  if (!(holder && holder->held_motion(pts, fps, bounds, &worst, &fall)) &&
      !motion_need(pts, fps, bounds, &worst, &fall))
    return 1;
  // the fall from rest in one substep, acc dt^2, at most bounds.fall r
  worst = std::max(worst, std::sqrt(fall / bounds.fall) / fps);
  return static_cast<int>(std::min<double>(most, std::ceil(worst)));
}

}  // namespace grains
