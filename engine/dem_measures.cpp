#include "engine/dem_measures.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace grains {

MeanSd mean_sd(const std::vector<double>& values) {
  MeanSd out;
  if (values.empty()) return out;
  for (double a : values) out.mean += a;
  out.mean /= values.size();
  double v = 0;
  for (double a : values) v += (a - out.mean) * (a - out.mean);
  out.sd = values.size() > 1 ? std::sqrt(v / (values.size() - 1)) : 0;
  return out;
}

HeapAngle heap_angle(const ParticleStore& pts, double d, double cx, double cz, int sectors) {
  HeapAngle out;
  const float* P = pts.v3_if("P");
  const float* ps = pts.f_if("pscale");
  const float* mass = pts.f_if("mass");
  if (!P || !(d > 0) || sectors < 1) return out;
  const double pi = std::acos(-1.0);
  // top[s][b]: highest grain top in sector s, ring b (0 where empty); rings grow as needed
  std::vector<std::vector<double>> top(sectors);
  for (size_t k = 0; k < pts.size(); ++k) {
    if (mass && !(mass[k] > 0)) continue;
    const double x = P[3 * k] - cx, z = P[3 * k + 2] - cz;
    const double y = P[3 * k + 1] + (ps ? ps[k] : d / 2);
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) continue;
    ++out.grains;
    out.peak = std::max(out.peak, y);
    const int s = static_cast<int>((std::atan2(z, x) + pi) / (2 * pi) * sectors) % sectors;
    const double rr = std::hypot(x, z) / d;
    if (rr > 1e6) continue;
    const size_t b = static_cast<size_t>(rr);
    if (b >= top[s].size()) top[s].resize(b + 1, 0.0);
    top[s][b] = std::max(top[s][b], y);
  }
  std::vector<double> angles;
  double feet = 0;
  for (int s = 0; s < sectors; ++s) {
    const std::vector<double>& prof = top[s];
    size_t foot = prof.size();
    for (size_t b = 0; b < prof.size(); ++b)
      if (prof[b] < 1.5 * d && b * d > 2 * d) {
        foot = b;
        break;
      }
    feet += foot * d;
    double n = 0, mx = 0, my = 0, sxx = 0, sxy = 0;
    std::vector<std::pair<double, double>> flank;
    for (size_t b = 0; b < foot; ++b)
      if (prof[b] >= 0.2 * out.peak && prof[b] <= 0.8 * out.peak)
        flank.push_back({(b + 0.5) * d, prof[b]});
    if (flank.size() < 3) continue;
    for (auto& [x, y] : flank) n += 1, mx += x, my += y;
    mx /= n, my /= n;
    for (auto& [x, y] : flank) sxx += (x - mx) * (x - mx), sxy += (x - mx) * (y - my);
    angles.push_back(std::atan(-sxy / sxx) * 180 / pi);
  }
  out.foot_radius = feet / sectors;
  out.cone_deg = out.foot_radius > 0 ? std::atan(out.peak / out.foot_radius) * 180 / pi : 0;
  out.sectors = static_cast<int>(angles.size());
  if (angles.empty()) return out;
  const MeanSd a = mean_sd(angles);
  out.angle_deg = a.mean;
  out.spread_deg = a.sd;
  return out;
}

CollapseMetric collapse_metric(const ParticleStore& initial, const ParticleStore& final_state,
                               double d) {
  CollapseMetric m;
  auto extent = [](const ParticleStore& s, int axis) {
    const float* P = s.v3_if("P");
    const float* r = s.f_if("pscale");
    double hi = 0;
    for (size_t k = 0; k < s.size(); ++k)
      hi = std::max(hi, double(P[3 * k + axis]) + (r ? r[k] : 0));
    return hi;
  };
  m.L0 = extent(initial, 0);
  m.H0 = extent(initial, 1);
  m.H = extent(final_state, 1);
  const float* P = final_state.v3_if("P");
  if (!P || final_state.size() == 0 || !(d > 0) || !(m.L0 > 0)) return m;
  double zlo = 1e30, zhi = -1e30, xhi = 0;
  for (size_t k = 0; k < final_state.size(); ++k) {
    zlo = std::min(zlo, double(P[3 * k + 2]));
    zhi = std::max(zhi, double(P[3 * k + 2]));
    xhi = std::max(xhi, double(P[3 * k]));
  }
  const double threshold = 0.5 * (zhi - zlo + d) / d;
  std::vector<size_t> count(static_cast<size_t>(std::max(0.0, xhi / d)) + 2, 0);
  for (size_t k = 0; k < final_state.size(); ++k)
    count[static_cast<size_t>(std::max(0.0, double(P[3 * k]) / d))]++;
  size_t b = 0;
  while (b < count.size() && count[b] >= threshold) ++b;
  m.L = b * d;
  for (size_t k = b; k < count.size(); ++k) m.beyond += count[k];
  m.runout = (m.L - m.L0) / m.L0;
  m.height = m.H / m.L0;
  return m;
}

}  // namespace grains
