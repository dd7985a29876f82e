// `grains-lab laws`: validation against published granular laws. See lab/validation.h and
// bench/validation/README.md.
#include "lab/validation.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>

#include "cli/options.h"
#include "engine/dem_measures.h"
#include "engine/graph.h"
#include "engine/node.h"
#include "engine/simulation.h"
#include "lab/source.h"

namespace fs = std::filesystem;

namespace grains {
namespace {

constexpr double kG = 9.81;
constexpr double kPi = 3.14159265358979323846;

std::string num(double v, int digits = 3) {
  if (!std::isfinite(v)) return "nan";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

std::string vec(double x, double y, double z) {
  return "[" + num(x, 9) + "," + num(y, 9) + "," + num(z, 9) + "]";
}

}  // namespace

std::string contact_solver_of(const LawSettings& s) {
  if (!s.contact_solver.empty()) return s.contact_solver;
  const NodeTypeInfo* info = find_node_type("grains");
  const ParamDecl* decl = info ? info->find_param("contact_solver") : nullptr;
  if (!decl) throw std::logic_error("no parameter grains.contact_solver");
  return decl->def_string;  // a menu's default choice (ParamDecl::menu_of)
}

namespace {

std::vector<Override> common_overrides(const LawSettings& s, const std::string& source) {
  return {parse_override(source + ".separation=" + num(s.d, 9)),
          parse_override("grains.particle_separation=" + num(s.d, 9)),
          parse_override("solver.substeps=" + std::to_string(s.substeps)),
          // fixed settings: error control would pick its own substeps
          parse_override(std::string("solver.error_control=") + (s.error_control ? "1" : "0")),
          parse_override("grains.constraint_iterations=" + std::to_string(s.iterations)),
          parse_override("grains.friction_with_particles=" + num(s.friction, 9)),
          parse_override("grains.contact_solver=" + contact_solver_of(s))};
}

// a node type's default for an int parameter (the registry's declaration, so that the lab's
// "defaults" follow the nodes')
int node_default(const std::string& type, const std::string& param) {
  const NodeTypeInfo* info = find_node_type(type);
  const ParamDecl* decl = info ? info->find_param(param) : nullptr;
  if (!decl) throw std::logic_error("no parameter " + type + "." + param);
  return static_cast<int>(decl->def[0]);
}

// "8x40", or "defaults" for the node defaults with error control
std::string solver_tag(const LawSettings& s) {
  return s.error_control ? std::string("defaults")
                         : std::to_string(s.substeps) + "x" + std::to_string(s.iterations);
}

// the solver setting as a sentence, for the report's method lines
std::string solver_sentence(const LawSettings& s) {
  if (s.error_control)
    return "the node defaults (" + std::to_string(s.iterations) +
           " iterations, error control picking the substeps), contact_solver " + contact_solver_of(s);
  return std::to_string(s.substeps) + " substeps x " + std::to_string(s.iterations) +
         " iterations, contact_solver " + contact_solver_of(s);
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Fits

LineFit fit_line(const std::vector<double>& x, const std::vector<double>& y) {
  LineFit f;
  f.n = std::min(x.size(), y.size());
  if (f.n < 2) return f;
  double mx = 0, my = 0;
  for (size_t k = 0; k < f.n; ++k) mx += x[k], my += y[k];
  mx /= f.n, my /= f.n;
  double sxx = 0, sxy = 0, syy = 0;
  for (size_t k = 0; k < f.n; ++k) {
    sxx += (x[k] - mx) * (x[k] - mx);
    sxy += (x[k] - mx) * (y[k] - my);
    syy += (y[k] - my) * (y[k] - my);
  }
  if (sxx <= 0) return f;
  f.slope = sxy / sxx;
  f.intercept = my - f.slope * mx;
  f.r2 = syy > 0 ? sxy * sxy / (sxx * syy) : 1;
  return f;
}

PowerFit fit_power(const std::vector<double>& x, const std::vector<double>& y) {
  std::vector<double> lx, ly;
  for (size_t k = 0; k < std::min(x.size(), y.size()); ++k)
    if (x[k] > 0 && y[k] > 0) lx.push_back(std::log(x[k])), ly.push_back(std::log(y[k]));
  LineFit l = fit_line(lx, ly);
  return {l.slope, std::exp(l.intercept), l.r2};
}

// ---------------------------------------------------------------------------------------------
// Measurements

double deposit_radius(const ParticleStore& pts, double cx, double cz, double d) {
  const float* P = pts.v3_if("P");
  if (!P || pts.size() == 0) return 0;
  std::vector<double> radii, count;
  for (size_t k = 0; k < pts.size(); ++k) {
    double r = std::hypot(P[3 * k] - cx, P[3 * k + 2] - cz);
    radii.push_back(r);
    size_t b = static_cast<size_t>(r / d);
    if (b >= count.size()) count.resize(b + 1, 0);
    count[b] += 1;
  }
  // cover of ring b (d wide): count (pi d^2 / 4) / (pi ((b+1)^2 - b^2) d^2) = count / (4 (2b + 1))
  auto cover = [&](size_t b) { return b < count.size() ? count[b] / (4.0 * (2 * b + 1)) : 0.0; };
  // start at the ring of the median radius (covered in any deposit; the innermost rings are
  // small and may hold no centre at all), then walk out
  std::nth_element(radii.begin(), radii.begin() + radii.size() / 2, radii.end());
  size_t b = static_cast<size_t>(radii[radii.size() / 2] / d);
  while (b < count.size() && cover(b) >= 0.5) ++b;
  if (b == 0) return 0;
  // interpolate between the centres of rings b-1 (>= 0.5) and b (< 0.5)
  double c0 = cover(b - 1), c1 = cover(b);
  double t = c0 > c1 ? (c0 - 0.5) / (c0 - c1) : 0;
  return (b - 0.5 + t) * d;
}

double deposit_height(const ParticleStore& pts) {
  const float* P = pts.v3_if("P");
  const float* r = pts.f_if("pscale");
  double h = 0;
  for (size_t k = 0; k < pts.size(); ++k) h = std::max(h, double(P[3 * k + 1]) + (r ? r[k] : 0));
  return h;
}

namespace {

// the positions (P, pscale) of the moving grains (mass > 0) below y_max: fixed grains are a bed
ParticleStore moving_grains(const ParticleStore& pts, double y_max = 1e30) {
  const float* P = pts.v3_if("P");
  const float* ps = pts.f_if("pscale");
  const float* mass = pts.f_if("mass");
  std::vector<size_t> keep;
  for (size_t k = 0; P && k < pts.size(); ++k)
    if (P[3 * k + 1] <= y_max && (!mass || mass[k] > 0)) keep.push_back(k);
  ParticleStore out;
  out.add_points(keep.size());
  float* Q = out.v3("P");
  for (size_t j = 0; j < keep.size(); ++j)
    for (int c = 0; c < 3; ++c) Q[3 * j + c] = P[3 * keep[j] + c];
  if (ps) {  // a second attribute may move the first: P is written before it is added
    float* r = out.f("pscale");
    for (size_t j = 0; j < keep.size(); ++j) r[j] = ps[keep[j]];
  }
  return out;
}

}  // namespace

PileSlope pile_slope(const ParticleStore& pts, double cx, double cz, double d, double y_max,
                     int sectors) {
  PileSlope out;
  if (!pts.v3_if("P") || pts.size() == 0 || sectors < 1) return out;
  // the moving grains below y_max (fixed grains, mass 0, are the bed, not the pile)
  const ParticleStore pile = moving_grains(pts, y_max);
  const float* P = pile.v3_if("P");
  const float* ps = pile.f_if("pscale");
  out.radius = deposit_radius(pile, cx, cz, d);
  // top[s][b]: highest grain top in sector s, ring b (d wide); -1 where empty
  std::vector<std::vector<double>> top(sectors);
  for (size_t k = 0; k < pile.size(); ++k) {
    double x = P[3 * k] - cx, z = P[3 * k + 2] - cz, y = P[3 * k + 1] + (ps ? ps[k] : d / 2);
    double phi = std::atan2(z, x) + kPi;  // [0, 2 pi]
    int s = std::min(sectors - 1, static_cast<int>(phi / (2 * kPi) * sectors));
    size_t b = static_cast<size_t>(std::hypot(x, z) / d);
    if (b >= top[s].size()) top[s].resize(b + 1, -1);
    top[s][b] = std::max(top[s][b], y);
  }
  std::vector<double> angles, heights;
  for (int s = 0; s < sectors; ++s) {
    std::vector<double> rx, hy;
    for (size_t b = 0; b < top[s].size(); ++b) {
      double r = (b + 0.5) * d;
      if (top[s][b] >= 0 && r >= 0.2 * out.radius && r <= 0.8 * out.radius)
        rx.push_back(r), hy.push_back(top[s][b]);
    }
    if (!top[s].empty()) heights.push_back(*std::max_element(top[s].begin(), top[s].end()));
    if (rx.size() < 3) continue;
    LineFit f = fit_line(rx, hy);
    angles.push_back(std::atan(-f.slope) * 180 / kPi);
  }
  if (!heights.empty()) {  // the median over sectors: a lone chain of grains moves one sector
    std::nth_element(heights.begin(), heights.begin() + heights.size() / 2, heights.end());
    out.height = heights[heights.size() / 2];
  }
  out.sectors = static_cast<int>(angles.size());
  if (angles.empty()) return out;
  const MeanSd a = mean_sd(angles);
  out.angle_deg = a.mean;
  out.spread_deg = a.sd;
  return out;
}

// ---------------------------------------------------------------------------------------------
// Experiments

CollapseResult run_collapse(const std::string& scene, double aspect, int radius_grains,
                            const LawSettings& s, int threads) {
  auto t0 = std::chrono::steady_clock::now();
  CollapseResult res;
  res.planned = aspect;
  res.r0 = radius_grains * s.d;
  // a loose lattice (kCollapseSpacing d apart) carved to the cylinder of radius R0, built
  // 1 / kCollapseCompaction times the planned height
  const double spacing = kCollapseSpacing * s.d;
  const int layers = std::max(
      1, static_cast<int>(std::lround(aspect * res.r0 / kCollapseCompaction / spacing)));
  res.h_built = layers * spacing;
  const double bed = s.d;  // the rough bed's top (data/rough_bed.ply)
  std::vector<Override> ov = common_overrides(s, "column");
  ov.push_back(parse_override("column.separation=" + num(spacing, 9)));
  ov.push_back(parse_override("column.pscale=" + num(s.d / 2, 9)));
  ov.push_back(parse_override("column.center=" + vec(0, bed + res.h_built / 2, 0)));
  ov.push_back(parse_override("column.size=" + vec(2 * res.r0, res.h_built, 2 * res.r0)));
  ov.push_back(parse_override("carve.radius=" + num(res.r0, 9)));
  // the bed reaches past the run-out of 1.5 x the larger published law, where one is left
  const double reach = res.r0 * (1 + 1.5 * std::max(lube2004_runout(aspect), lajeunesse2004_runout(aspect)));
  ov.push_back(parse_override("bed_trim.radius=" + num(std::min(kBedRadius, reach + 5 * s.d), 9)));
  // the lattice falls its height in sqrt(2 H / g); as long again and a quarter second to come
  // to rest; the tube (data/tube.obj, radius 1) holds the grains' centres within R0 until the
  // end of that frame, then its wall moves out along its normal: nothing drags the column
  Graph g = load_graph(scene, ov);
  const int release =
      static_cast<int>(std::ceil((0.25 + 2 * std::sqrt(2 * res.h_built / kG)) * g.fps));
  res.release = release / g.fps;
  const double tube = res.r0 + s.d / 2;
  ov.push_back(parse_override("tube.scale=if($T < " + num(res.release + 0.5 / g.fps, 9) + ", " +
                              num(tube, 9) + ", " + num(100 * tube, 9) + ")"));
  g = load_graph(scene, ov);
  // the column falls in about sqrt(2 H0 / g) and spreads for about 3 sqrt(H0 / g) (Lube 2004);
  // 0.75 s more lets the front stop
  const double t_end = res.release + 0.75 + 4 * std::sqrt(aspect * res.r0 / kG);
  g.frames = static_cast<int>(std::ceil(t_end * g.fps));
  int earlier = std::max(1, g.frames - static_cast<int>(std::lround(0.25 * g.fps)));
  Simulation sim(g, threads);
  for (int f = 1; f <= g.frames; ++f) {
    sim.step_frame();
    spdlog::debug("  frame {}: {}", f, frame_detail(sim.object(0).stats));
    if (f == release) {
      const ParticleStore column = moving_grains(sim.object(0).pts);
      res.grains = column.size();
      res.r0_measured = deposit_radius(column, 0, 0, s.d);
      res.h0 = pile_slope(column, 0, 0, s.d).height - bed;
      res.aspect = res.h0 / res.r0;
    }
    if (f == earlier) res.r_inf_earlier = deposit_radius(moving_grains(sim.object(0).pts), 0, 0, s.d);
  }
  const ParticleStore deposit = moving_grains(sim.object(0).pts);
  res.r_inf = deposit_radius(deposit, 0, 0, s.d);
  res.h_inf = pile_slope(deposit, 0, 0, s.d).height - bed;
  res.runout = (res.r_inf - res.r0) / res.r0;
  res.frames = g.frames;
  res.seconds = seconds_since(t0);
  return res;
}

SiloResult run_silo(const std::string& scene, int orifice_grains, const SiloSize& size,
                    const LawSettings& s, int threads) {
  auto t0 = std::chrono::steady_clock::now();
  SiloResult res;
  res.orifice = orifice_grains * s.d;
  double half = size.width_grains * s.d / 2, fill = size.fill_grains * s.d;
  std::vector<Override> ov = common_overrides(s, "fill");
  ov.push_back(parse_override("fill.center=" + vec(0, fill / 2, 0)));
  ov.push_back(parse_override("fill.size=" + vec(2 * half, fill, 2 * half)));
  ov.push_back(parse_override("wall_xm.translate=" + vec(-half, 0, 0)));
  ov.push_back(parse_override("wall_xp.translate=" + vec(half, 0, 0)));
  ov.push_back(parse_override("wall_zm.translate=" + vec(0, 0, -half)));
  ov.push_back(parse_override("wall_zp.translate=" + vec(0, 0, half)));
  // four floor plates 1 m square, 2 cm thick, top at y = 0, each shifted off the axis so that
  // they leave a square hole of side D between them (they overlap beyond the hole's corners)
  double off = res.orifice / 2 + 0.5;
  ov.push_back(parse_override("floor_xm.translate=" + vec(-off, -0.01, 0)));
  ov.push_back(parse_override("floor_xp.translate=" + vec(off, -0.01, 0)));
  ov.push_back(parse_override("floor_zm.translate=" + vec(0, -0.01, -off)));
  ov.push_back(parse_override("floor_zp.translate=" + vec(0, -0.01, off)));
  Graph g = load_graph(scene, ov);
  g.frames = static_cast<int>(std::ceil(size.t_end * g.fps - 1e-9));
  Simulation sim(g, threads);
  std::vector<double> t, n;
  for (int f = 1; f <= g.frames; ++f) {
    sim.step_frame();
    spdlog::debug("  frame {}: {}", f, frame_detail(sim.object(0).stats));
    const ParticleStore& pts = sim.object(0).pts;
    double time = f / g.fps;
    if (f == 1) res.grains = pts.size();
    if (time >= size.t_start - 1e-9) {
      if (t.empty()) {
        // bulk number density: the grains in the silo (above its floor) over the silo's
        // cross-section times the fill's height (the 95th percentile of their y, plus a
        // radius); it counts the flowing, dilated zone too, and an unconverged fill's
        // compaction, which is what our material's bulk density is
        const float* P = pts.v3_if("P");
        std::vector<double> ys;
        for (size_t k = 0; k < pts.size(); ++k)
          if (P[3 * k + 1] > 0) ys.push_back(P[3 * k + 1]);
        if (!ys.empty()) {
          size_t q = std::min(ys.size() - 1, static_cast<size_t>(0.95 * ys.size()));
          std::nth_element(ys.begin(), ys.begin() + q, ys.end());
          double h = ys[q] + s.d / 2;
          res.number_density = ys.size() / (4 * half * half * h);
        }
      }
      t.push_back(time);
      n.push_back(static_cast<double>(pts.size()));
    }
  }
  LineFit all = fit_line(t, n);
  res.rate = -all.slope;
  res.r2 = all.r2;
  size_t mid = t.size() / 2;
  res.rate_first =
      -fit_line({t.begin(), t.begin() + mid + 1}, {n.begin(), n.begin() + mid + 1}).slope;
  res.rate_second = -fit_line({t.begin() + mid, t.end()}, {n.begin() + mid, n.end()}).slope;
  res.drained = res.grains > 0 && !n.empty() ? 1.0 - n.back() / res.grains : 0;
  res.frames = g.frames;
  res.seconds = seconds_since(t0);
  return res;
}

BeverlooFit fit_beverloo(const std::vector<SiloResult>& runs, double d) {
  BeverlooFit f;
  std::vector<double> D, W;
  double dmin = 1e30;
  for (const auto& r : runs)
    if (r.rate > 0) D.push_back(r.orifice), W.push_back(r.rate), dmin = std::min(dmin, r.orifice);
  if (D.size() < 2) return f;
  auto fit_k = [&](double k) {
    std::vector<double> x;
    for (double v : D) x.push_back(v - k * d);
    return fit_power(x, W);
  };
  PowerFit p14 = fit_k(kBeverlooK);
  f.exponent_k14 = p14.exponent;
  f.r2_k14 = p14.r2;
  // n = 5/2: rate^(2/5) = (C n_b sqrt(g))^(2/5) (D - k d), a line through D = k d
  std::vector<double> w25;
  for (double v : W) w25.push_back(std::pow(v, 0.4));
  LineFit lin = fit_line(D, w25);
  if (lin.slope > 0) f.k_linear = -lin.intercept / lin.slope / d, f.r2_linear = lin.r2;
  // k and n together: scan k over [0, D_min / d) for the best log-log fit
  double best = -1;
  for (double k = 0; k < dmin / d - 0.05; k += 0.005) {
    PowerFit p = fit_k(k);
    if (p.r2 > best) best = p.r2, f.exponent_free = p.exponent, f.k_free = k, f.r2_free = p.r2;
  }
  double cmin = 1e30, cmax = -1e30, sum = 0;
  int count = 0;
  for (const auto& r : runs) {
    double base = r.orifice - kBeverlooK * d;
    if (r.rate <= 0 || base <= 0 || r.number_density <= 0) continue;
    double c = r.rate / (r.number_density * std::sqrt(kG) * std::pow(base, 2.5));
    sum += c, ++count, cmin = std::min(cmin, c), cmax = std::max(cmax, c);
  }
  if (count) f.c = sum / count, f.c_spread = cmax - cmin;
  return f;
}

ReposeResult run_repose(const std::string& scene, double friction, const ReposeSize& size,
                        const LawSettings& s, int threads) {
  auto t0 = std::chrono::steady_clock::now();
  ReposeResult res;
  res.friction = friction;
  LawSettings ls = s;
  ls.friction = friction;
  std::vector<Override> ov = common_overrides(ls, "fill");
  // a square funnel: four plates at size.funnel_deg from the horizontal, from a square hole of
  // side `orifice` (at hopper_floor) up to the hopper's vertical walls; the fill stands above it.
  // Frictionless walls on a slope leave no dead zone: on the flat floor of a 10 d hopper with a
  // 6 d hole the grains above the two-grain ledges stood (768 of 1,200 left with gauss_seidel)
  const double half = size.hopper_grains * s.d / 2, fill = size.fill_grains * s.d;
  const double a = size.orifice_grains * s.d / 2, y0 = size.hopper_floor;
  const double th = size.funnel_deg * kPi / 180, c = std::cos(th), sn = std::sin(th);
  const double y_top = y0 + (half - a) * std::tan(th);
  ov.push_back(parse_override("fill.center=" + vec(0, y_top + s.d / 2 + fill / 2, 0)));
  ov.push_back(parse_override("fill.size=" + vec(2 * half, fill, 2 * half)));
  const double wall_h = y_top - y0 + fill + 4 * s.d, wall_y = y0 + wall_h / 2;
  ov.push_back(parse_override("wall_xm.translate=" + vec(-half - s.d / 2, wall_y, 0)));
  ov.push_back(parse_override("wall_xp.translate=" + vec(half + s.d / 2, wall_y, 0)));
  ov.push_back(parse_override("wall_zm.translate=" + vec(0, wall_y, -half - s.d / 2)));
  ov.push_back(parse_override("wall_zp.translate=" + vec(0, wall_y, half + s.d / 2)));
  for (const char* w : {"wall_xm", "wall_xp"})
    ov.push_back(parse_override(std::string(w) + ".size=" + vec(s.d, wall_h, 2 * half + 2 * s.d)));
  for (const char* w : {"wall_zm", "wall_zp"})
    ov.push_back(parse_override(std::string(w) + ".size=" + vec(2 * half + 2 * s.d, wall_h, s.d)));
  // each plate d thick, its top face from the hole's edge up the slope and 2 d into the wall
  const double t = s.d, len = (half - a) / c + 2 * s.d, w = 2 * half + 2 * s.d;
  const double along = a + len / 2 * c + t / 2 * sn, up = y0 + len / 2 * sn - t / 2 * c;
  const std::string deg = num(size.funnel_deg, 9), neg = num(-size.funnel_deg, 9);
  ov.push_back(parse_override("floor_xp.translate=" + vec(along, up, 0)));
  ov.push_back(parse_override("floor_xp.rotate=[0,0," + deg + "]"));
  ov.push_back(parse_override("floor_xm.translate=" + vec(-along, up, 0)));
  ov.push_back(parse_override("floor_xm.rotate=[0,0," + neg + "]"));
  ov.push_back(parse_override("floor_zp.translate=" + vec(0, up, along)));
  ov.push_back(parse_override("floor_zp.rotate=[" + neg + ",0,0]"));
  ov.push_back(parse_override("floor_zm.translate=" + vec(0, up, -along)));
  ov.push_back(parse_override("floor_zm.rotate=[" + deg + ",0,0]"));
  for (const char* f : {"floor_xm", "floor_xp"})
    ov.push_back(parse_override(std::string(f) + ".size=" + vec(len, t, w)));
  for (const char* f : {"floor_zm", "floor_zp"})
    ov.push_back(parse_override(std::string(f) + ".size=" + vec(w, t, len)));
  ov.push_back(parse_override("bed_trim.radius=" + num(size.bed_radius, 9)));
  Graph g = load_graph(scene, ov);
  g.frames = size.frames;
  int earlier = std::max(1, g.frames - static_cast<int>(std::lround(g.fps)));
  Simulation sim(g, threads);
  double y_max = y0 - s.d;  // the pile: grains below the hopper's floor
  for (int f = 1; f <= g.frames; ++f) {
    sim.step_frame();
    spdlog::debug("  frame {}: {}", f, frame_detail(sim.object(0).stats));
    if (f == earlier) res.slope_earlier = pile_slope(sim.object(0).pts, 0, 0, s.d, y_max);
  }
  const ParticleStore& pts = sim.object(0).pts;
  const float* P = pts.v3_if("P");
  const float* m = pts.f_if("mass");
  for (size_t k = 0; k < pts.size(); ++k) {
    if (m && m[k] <= 0) continue;
    ++res.grains;
    if (P[3 * k + 1] > y_max) ++res.left_in_hopper;
  }
  res.slope = pile_slope(pts, 0, 0, s.d, y_max);
  res.frames = g.frames;
  res.seconds = seconds_since(t0);
  return res;
}

// ---------------------------------------------------------------------------------------------
// Plan and expectations

ValidationPlan validation_plan(bool quick) {
  ValidationPlan p;
  if (quick) {
    p.solver_settings = {{0, 0}};
    p.aspects = {0.5, 1, 2, 4};
    p.column_radius_grains = 6;
    p.orifices = {6, 7, 8, 9};
    p.silo = {24, 20, 0.75, 1.5};
    p.frictions = {0.2, 0.5, 1.0};
    p.pile = {10, 12, 6, 0.45, 0.3, 96};
  } else {
    p.solver_settings = {{0, 0}, {8, 40}};
    p.aspects = {0.5, 1, 2, 4};
    p.column_radius_grains = 10;
    p.orifices = {5, 6, 7, 8, 9};
    p.silo = {24, 24, 0.75, 1.75};
    p.frictions = {0.1, 0.2, 0.35, 0.5, 0.75, 1.0};
    p.pile = {12, 18, 6, 0.55, 0.45, 144};
  }
  return p;
}

LawSettings law_settings(const ValidationPlan& plan, std::pair<int, int> solver_setting) {
  const auto [substeps, iterations] = solver_setting;
  LawSettings s = plan.settings;
  s.error_control = substeps == 0 && iterations == 0;
  s.substeps = s.error_control ? node_default("solver", "substeps") : substeps;
  s.iterations = s.error_control ? node_default("grains", "constraint_iterations") : iterations;
  return s;
}

double lube2004_runout(double a) {
  return a <= 1.7 ? 1.24 * a : 1.6 * std::sqrt(a);
}
double lajeunesse2004_runout(double a) {
  return a <= 0.74 ? 1.0 * a : 2.0 * std::sqrt(a);
}

// ---------------------------------------------------------------------------------------------
// The command

namespace {

struct LawRow {
  std::string law, source, quantity;
  std::string expected;                            // as printed (a value or a band)
  double expected_low = NAN, expected_high = NAN;  // the band (equal for a single value)
  double ours = NAN;
  double difference = NAN;  // ours - expected value, or distance outside the band (0 inside)
  size_t grains = 0;
  std::string settings;
  double seconds = 0;
};

double outside(double v, double lo, double hi) {
  return v < lo ? v - lo : (v > hi ? v - hi : 0);
}

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

std::string settings_text(const LawSettings& s, const std::string& extra) {
  return solver_tag(s) + " d=" + num(s.d) +
         " mu=" + num(s.friction) + (extra.empty() ? "" : " " + extra);
}

std::string machine_text(int threads) {
  std::string cpu = "unknown cpu";
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("model name", 0) == 0) {
      auto c = line.find(':');
      if (c != std::string::npos) cpu = line.substr(line.find_first_not_of(" \t", c + 1));
      break;
    }
  double load = 0;
  std::ifstream("/proc/loadavg") >> load;
  return cpu + ", " + std::to_string(sysconf(_SC_NPROCESSORS_ONLN)) + " cores; " +
         std::to_string(threads) + " OpenMP thread(s); 1-minute load average " + num(load) +
         " when it started";
}

}  // namespace

const char* validation_csv_header() {
  return "law,source,quantity,expected,expected_low,expected_high,ours,difference,grains,settings,"
         "wall_s";
}

int run_validation(const ValidationOptions& o) {
  auto want = [&](const std::string& what) {
    return o.only.empty() || std::find(o.only.begin(), o.only.end(), what) != o.only.end();
  };
  std::string collapse_scene = o.scenes_dir + "/column_collapse.json";
  std::string silo_scene = o.scenes_dir + "/silo_discharge.json";
  std::string pile_scene = o.scenes_dir + "/angle_of_repose.json";
  // every scene loads before anything runs
  if (want("collapse")) load_graph(collapse_scene);
  if (want("silo")) load_graph(silo_scene);
  if (want("repose")) load_graph(pile_scene);
  ValidationPlan plan = validation_plan(o.quick);
  if (o.substeps > 0 || o.iterations > 0) {
    // fixed settings; a value not given is the fixed reference's (LawSettings: 8 x 40)
    const LawSettings fixed;
    plan.solver_settings = {{o.substeps > 0 ? o.substeps : fixed.substeps,
                             o.iterations > 0 ? o.iterations : fixed.iterations}};
  }
  if (o.defaults) plan.solver_settings = {{0, 0}};
  if (o.friction >= 0) plan.settings.friction = o.friction;
  if (!o.contact_solver.empty()) plan.settings.contact_solver = o.contact_solver;
  int threads =
      o.threads > 0 ? o.threads : static_cast<int>(std::max(1L, sysconf(_SC_NPROCESSORS_ONLN)));
  fs::create_directories(o.out_dir);
  std::string started = [] {
    std::time_t now = std::time(nullptr);
    char buf[64];
    std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
    return std::string(buf);
  }();
  std::string machine = machine_text(threads);

  std::vector<LawRow> rows;
  std::ostringstream detail;  // per-experiment Markdown tables

  for (auto [substeps, iterations] : plan.solver_settings) {
    const LawSettings s = law_settings(plan, {substeps, iterations});
    std::string tag = solver_tag(s);

    if (want("collapse")) {
      std::vector<CollapseResult> runs;
      for (double a : plan.aspects) {
        CollapseResult r = run_collapse(collapse_scene, a, plan.column_radius_grains, s, threads);
        spdlog::info(
            "laws {} collapse a={:.3g}  {} grains  R0 {:.3g} m (measured {:.3g})  R_inf {:.3g} m "
            " run-out {:.3g}  {:.1f} s",
            tag, r.aspect, r.grains, r.r0, r.r0_measured, r.r_inf, r.runout, r.seconds);
        runs.push_back(r);
      }
      std::string set = settings_text(s, "R0=" + std::to_string(plan.column_radius_grains) + "d");
      for (const auto& r : runs) {
        for (int src = 0; src < 2; ++src) {
          LawRow row;
          row.law = "column collapse run-out at a=" + num(r.aspect);
          row.source =
              src == 0
                  ? "Lube et al. 2004 (JFM 508): 1.24a for a<=1.7, 1.6a^0.5 above"
                  : "Lajeunesse et al. 2004 (Phys. Fluids 16): 1.0a for a<=0.74, 2.0a^0.5 above";
          row.quantity = "(R_inf-R0)/R0";
          double e = src == 0 ? lube2004_runout(r.aspect) : lajeunesse2004_runout(r.aspect);
          row.expected = num(e);
          row.expected_low = row.expected_high = e;
          row.ours = r.runout;
          row.difference = r.runout - e;
          row.grains = r.grains;
          row.settings = set;
          row.seconds = r.seconds;
          rows.push_back(row);
        }
      }
      // the regime exponent above a = 1.7 (both sources: 1/2)
      std::vector<double> ax, ry;
      double secs = 0;
      size_t grains = 0;
      for (const auto& r : runs) {
        secs += r.seconds;
        if (r.aspect > 1.7) ax.push_back(r.aspect), ry.push_back(r.runout), grains += r.grains;
      }
      if (ax.size() >= 2) {
        PowerFit p = fit_power(ax, ry);
        LawRow row;
        row.law = "column collapse run-out exponent, a>1.7";
        row.source = "Lube 2004, Lajeunesse 2004: run-out ~ a^0.5 (Larrieu 2006: a^0.52)";
        row.quantity = "d ln(run-out)/d ln a";
        row.expected = "0.5";
        row.expected_low = row.expected_high = 0.5;
        row.ours = p.exponent;
        row.difference = p.exponent - 0.5;
        row.grains = grains;
        row.settings = set;
        row.seconds = secs;
        rows.push_back(row);
      }
      detail
          << "### Column collapse, " << tag << "\n\n"
          << "`" << collapse_scene << "`, R0 = " << plan.column_radius_grains
          << " d, d = " << num(s.d) << " m, " << solver_sentence(s) << ", friction "
          << num(s.friction) << ".\n\n"
          << "| a planned | a settled | grains | R0 (m) | H0 built (m) | H0 settled (m) | R0 measured "
             "(m) | R_inf (m) | R_inf 0.25 s earlier (m) | run-out | Lube 2004 | Lajeunesse 2004 | "
             "H_inf/R0 | frames | wall s |\n"
          << "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | "
             "---: | ---: | ---: |\n";
      for (const auto& r : runs)
        detail << "| " << num(r.planned) << " | " << num(r.aspect) << " | " << r.grains << " | "
               << num(r.r0) << " | " << num(r.h_built) << " | " << num(r.h0) << " | "
               << num(r.r0_measured) << " | " << num(r.r_inf) << " | " << num(r.r_inf_earlier)
               << " | " << num(r.runout) << " | " << num(lube2004_runout(r.aspect)) << " | "
               << num(lajeunesse2004_runout(r.aspect)) << " | " << num(r.h_inf / r.r0) << " | "
               << r.frames << " | " << num(r.seconds) << " |\n";
      detail << "\n";
    }

    if (want("silo")) {
      std::vector<SiloResult> runs;
      for (int od : plan.orifices) {
        SiloResult r = run_silo(silo_scene, od, plan.silo, s, threads);
        spdlog::info(
            "laws {} silo D={}d  {} grains  rate {:.4g} /s (halves {:.4g}, {:.4g})  drained "
            "{:.2f}  {:.1f} s",
            tag, od, r.grains, r.rate, r.rate_first, r.rate_second, r.drained, r.seconds);
        runs.push_back(r);
      }
      BeverlooFit f = fit_beverloo(runs, s.d);
      double secs = 0;
      size_t grains = 0;
      for (const auto& r : runs) secs += r.seconds, grains = std::max(grains, r.grains);
      std::string set =
          settings_text(s, "silo " + std::to_string(plan.silo.width_grains) + "d wide, fill " +
                               std::to_string(plan.silo.fill_grains) +
                               "d, D/d=" + std::to_string(plan.orifices.front()) + ".." +
                               std::to_string(plan.orifices.back()) + ", window " +
                               num(plan.silo.t_start) + "-" + num(plan.silo.t_end) + " s");
      auto add = [&](const std::string& law, const std::string& source, const std::string& q,
                     double e, double ours) {
        LawRow row;
        row.law = law;
        row.source = source;
        row.quantity = q;
        row.expected = num(e);
        row.expected_low = row.expected_high = e;
        row.ours = ours;
        row.difference = ours - e;
        row.grains = grains;
        row.settings = set;
        row.seconds = secs;
        rows.push_back(row);
      };
      add("Beverloo discharge exponent, k=1.4",
          "Beverloo et al. 1961; Nedderman et al. 1982 (k=1.4)", "n in W ~ (D-1.4d)^n",
          kBeverlooExponent, f.exponent_k14);
      add("Beverloo k with n=5/2 (W^(2/5) linear in D, r2=" + num(f.r2_linear, 4) + ")",
          "Beverloo 1961; Nedderman 1982: k=1.4 (DEM: 1.57-1.68, pbd_research.md s5)",
          "k: W^(2/5) = 0 at D = k d", kBeverlooK, f.k_linear);
      add("Beverloo constant, square orifice",
          "Beverloo 1961: C=0.58 x 4/pi for a square of side D",
          "C = W/(rho_b sqrt(g) (D-1.4d)^2.5)", kBeverlooC * 4 / kPi, f.c);
      // steadiness: the rate should not depend on the fill height (Beverloo; Janssen screening)
      double worst = 0;
      for (const auto& r : runs)
        if (r.rate > 0) worst = std::max(worst, std::fabs(r.rate_second - r.rate_first) / r.rate);
      add("Beverloo: rate independent of fill height", "Beverloo 1961; Mankoc et al. 2007",
          "max |second half - first half| / rate", 0, worst);
      detail << "### Silo discharge, " << tag << "\n\n"
             << "`" << silo_scene << "`, silo " << plan.silo.width_grains << " d square, filled "
             << plan.silo.fill_grains << " d high, d = " << num(s.d) << " m, "
             << solver_sentence(s) << ", friction " << num(s.friction)
             << "; rate fitted over t = " << num(plan.silo.t_start) << " to "
             << num(plan.silo.t_end) << " s.\n\n"
             << "| D/d | grains | rate (grains/s) | first half | second half | count fit r2 | n_b "
                "d^3 | C (n=2.5, k=1.4) | drained | wall s |\n"
             << "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n";
      for (const auto& r : runs) {
        double base = r.orifice - kBeverlooK * s.d;
        double c = base > 0 && r.number_density > 0
                       ? r.rate / (r.number_density * std::sqrt(kG) * std::pow(base, 2.5))
                       : NAN;
        detail << "| " << num(r.orifice / s.d) << " | " << r.grains << " | " << num(r.rate, 4)
               << " | " << num(r.rate_first, 4) << " | " << num(r.rate_second, 4) << " | "
               << num(r.r2, 4) << " | " << num(r.number_density * s.d * s.d * s.d) << " | "
               << num(c) << " | " << num(r.drained, 2) << " | " << num(r.seconds) << " |\n";
      }
      detail << "\nFits: n = " << num(f.exponent_k14) << " (k = 1.4, r2 " << num(f.r2_k14, 4)
             << "); k = " << num(f.k_linear) << " at n = 5/2 (r2 " << num(f.r2_linear, 4)
             << "); n and k together: n = " << num(f.exponent_free) << ", k = " << num(f.k_free)
             << " (r2 " << num(f.r2_free, 4) << "; over this range of D the two trade off, which "
             << "is why the Beverloo literature fixes one of them); C = " << num(f.c) << " (spread "
             << num(f.c_spread) << " over the orifices).\n\n";
    }

    if (want("repose")) {
      std::vector<ReposeResult> runs;
      for (double mu : plan.frictions) {
        ReposeResult r = run_repose(pile_scene, mu, plan.pile, s, threads);
        spdlog::info(
            "laws {} repose mu={:.3g}  {} grains ({} in the hopper)  angle {:.3g} deg (spread "
            "{:.2g}, {} sectors; 1 s earlier {:.3g})  height {:.3g} m  radius {:.3g} m  {:.1f} s",
            tag, mu, r.grains, r.left_in_hopper, r.slope.angle_deg, r.slope.spread_deg,
            r.slope.sectors, r.slope_earlier.angle_deg, r.slope.height, r.slope.radius, r.seconds);
        runs.push_back(r);
      }
      std::string band = num(kReposeDemLow) + "-" + num(kReposeDemHigh);
      std::string pile_text = "hopper " + std::to_string(plan.pile.hopper_grains) + "d, fill " +
                              std::to_string(plan.pile.fill_grains) + "d, hole " +
                              std::to_string(plan.pile.orifice_grains) + "d, " +
                              std::to_string(plan.pile.frames) + " frames";
      bool monotone = true;
      double secs = 0;
      for (size_t k = 0; k < runs.size(); ++k) {
        const auto& r = runs[k];
        secs += r.seconds;
        if (k > 0 && r.slope.angle_deg < runs[k - 1].slope.angle_deg) monotone = false;
        LawRow row;
        row.law = "angle of repose at friction " + num(r.friction);
        row.source = "DEM spheres, mu=0.4, rolling friction 0.02-0.2 (pbd_research.md s5)";
        row.quantity = "pile flank angle (deg)";
        row.expected = band;
        row.expected_low = kReposeDemLow;
        row.expected_high = kReposeDemHigh;
        row.ours = r.slope.angle_deg;
        row.difference = outside(r.slope.angle_deg, kReposeDemLow, kReposeDemHigh);
        row.grains = r.grains;
        LawSettings ls = s;
        ls.friction = r.friction;
        row.settings = settings_text(ls, pile_text);
        row.seconds = r.seconds;
        rows.push_back(row);
      }
      {
        double worst = 0;
        for (const auto& r : runs)
          worst = std::max(worst, std::fabs(r.slope.angle_deg - r.slope_earlier.angle_deg));
        LawRow row;
        row.law = "pile at rest: angle change over the last second";
        row.source = "a static pile keeps its angle (definition of the angle of repose)";
        row.quantity = "max |angle(end) - angle(end - 1 s)| (deg)";
        row.expected = "0";
        row.expected_low = row.expected_high = 0;
        row.ours = worst;
        row.difference = worst;
        row.seconds = 0;
        row.settings =
            solver_tag(s) + " " + pile_text;
        rows.push_back(row);
      }
      LawRow row;
      row.law = "angle of repose rises with friction";
      row.source = "Zhou et al. 2001 (PRE 64, 021301)";
      row.quantity =
          "monotone over mu=" + num(plan.frictions.front()) + ".." + num(plan.frictions.back());
      row.expected = "1 (monotone)";
      row.expected_low = row.expected_high = 1;
      row.ours = monotone ? 1 : 0;
      row.difference = row.ours - 1;
      row.seconds = secs;
      row.settings =
          solver_tag(s) + " " + pile_text;
      rows.push_back(row);
      detail << "### Angle of repose, " << tag << "\n\n"
             << "`" << pile_scene << "`, " << pile_text << "; d = " << num(s.d) << " m, "
             << solver_sentence(s) << ".\n\n"
             << "| friction | grains | left in hopper | angle (deg) | spread over sectors (deg) | "
                "sectors | angle 1 s earlier | height (m) | radius (m) | wall s |\n"
             << "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n";
      for (const auto& r : runs)
        detail << "| " << num(r.friction) << " | " << r.grains << " | " << r.left_in_hopper << " | "
               << num(r.slope.angle_deg) << " | " << num(r.slope.spread_deg, 2) << " | "
               << r.slope.sectors << " | " << num(r.slope_earlier.angle_deg) << " | "
               << num(r.slope.height) << " | " << num(r.slope.radius) << " | " << num(r.seconds)
               << " |\n";
      detail << "\n";
    }
  }  // solver settings

  // validation.csv
  std::string csv = o.out_dir + "/validation.csv";
  {
    std::ofstream out(csv);
    out << validation_csv_header() << "\n";
    for (const auto& r : rows)
      out << csv_field(r.law) << "," << csv_field(r.source) << "," << csv_field(r.quantity) << ","
          << csv_field(r.expected) << "," << num(r.expected_low, 6) << ","
          << num(r.expected_high, 6) << "," << num(r.ours, 6) << "," << num(r.difference, 6) << ","
          << r.grains << "," << csv_field(r.settings) << "," << num(r.seconds, 4) << "\n";
  }
  // the Markdown report
  {
    std::ofstream md(o.md_path);
    md << "# Validation against published granular laws\n\n"
       << "Written by `grains-lab laws` (lab/validation.cpp); the scenes, laws, sources and "
          "methods "
          "are "
          "in `bench/validation/README.md`, which also discusses every row that misses its law. "
          "Regenerate with:\n\n```\n"
       << o.command << "\n```\n\n"
       << "- **Date:** " << started << "\n- **Machine:** " << machine << "\n"
       << "- **Source:** commit `" << lab::source_commit().id << "`"
       << (lab::source_commit().dirty ? ", built with uncommitted changes (lab/source.h)" : "")
       << "\n"
       << "- **Plan:** " << (o.quick ? "quick (the tests' sizes)" : "full") << "\n\n"
       << "*difference* is ours minus the expected value; for a band, the distance outside it (0 "
          "inside).\n\n"
       << "| law | source | expected | ours | difference | grains | settings | wall s |\n"
       << "| --- | --- | ---: | ---: | ---: | ---: | --- | ---: |\n";
    for (const auto& r : rows)
      md << "| " << r.law << " | " << r.source << " | " << r.expected << " | " << num(r.ours)
         << " | " << num(r.difference, 2) << " | " << r.grains << " | " << r.settings << " | "
         << num(r.seconds) << " |\n";
    md << "\n## Measurements\n\n" << detail.str();
  }
  spdlog::info("wrote {} and {}", csv, o.md_path);
  return 0;
}

CLI::App* add_validation_command(CLI::App& app, ValidationOptions& o, int argc, char** argv) {
  auto* c = app.add_subcommand(
      "laws", "validation: run bench/validation's scenes and compare with published granular laws");
  c->add_option("--scenes", o.scenes_dir,
                "folder of the validation scenes (default bench/validation)");
  c->add_option("--out", o.out_dir, "output folder for validation.csv (default out/validation)");
  c->add_option("--md", o.md_path, "Markdown report to write (default VALIDATION.md)");
  c->add_flag("--quick", o.quick, "the tests' reduced sizes (a few minutes on one core)");
  c->add_option("--threads", o.threads, "worker threads (default: all cores)")
      ->check(CLI::Range(1, kMaxThreads));
  c->add_option("--only", o.only, "collapse, silo and/or repose (default: all)")
      ->check(CLI::IsMember({"collapse", "silo", "repose"}));
  auto* substeps = c->add_option("--substeps", o.substeps,
                                  "fixed substeps of every run (default: the plan's)")
                       ->check(positive_number());
  auto* iterations = c->add_option("--iterations", o.iterations,
                                    "fixed constraint iterations of every run (default: the plan's)")
                         ->check(positive_number());
  c->add_flag("--defaults", o.defaults,
              "every run at the node and solver defaults, error control picking the substeps (contact_solver "
              "as --contact-solver says)")
      ->excludes(substeps)
      ->excludes(iterations);
  c->add_option("--friction", o.friction, "friction_with_particles of the collapse and silo runs")
      ->check(non_negative_number());
  c->add_option("--contact-solver", o.contact_solver, "contact_solver of every run (default: the grains node's)")
      ->check(CLI::IsMember({"jacobi", "gauss_seidel"}));
  std::string cmd;
  for (int k = 0; k < argc; ++k) cmd += (k ? " " : "") + std::string(argv[k]);
  o.command = cmd;
  return c;
}

}  // namespace grains
