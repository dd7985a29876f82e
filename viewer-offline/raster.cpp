// render_frame: grains as ray-cast sphere splats into a z-buffer, ground patches, shading with
// screen-space occlusion, sphere-traced colliders, then edges and overlays (see render.h).
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "engine/mesh_shape.h"
#include "viewer-offline/render.h"

namespace grains::viewer {
namespace {

constexpr int kTile = 32;       // tile side (pixels) for binning spheres
constexpr float kNear = 1e-3f;  // near plane (m): grains closer than this are not drawn
constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr int32_t kNone = -1;  // id buffer: background
// id buffer: >= 0 a grain (global index), <= -2 the ground patch of plane collider (-2 - k)

// One grain in camera space with its clipped pixel bounds (inclusive); x0 > x1 when not drawn.
struct Splat {
  Vec3 c;        // centre, camera space (m)
  float r = 0;   // radius (m)
  float c2 = 0;  // |c|^2 - r^2
  int x0 = 1, y0 = 0, x1 = 0, y1 = 0;
};

// The exact screen interval covered by a sphere along one image axis: the two tangent lines from
// the eye to the circle (centre (u, z), radius r) in the plane containing that axis.
void tangent_interval(float u, float z, float r, float* lo, float* hi) {
  float d = std::sqrt(u * u + z * z);
  float a = std::atan2(u, z), b = std::asin(std::min(1.0f, r / d));
  *lo = std::tan(a - b);
  *hi = std::tan(a + b);
}

float smoothstep(float e0, float e1, float x) {
  float t = std::clamp((x - e0) / (e1 - e0), 0.0f, 1.0f);
  return t * t * (3 - 2 * t);
}

// a stable pseudo-random brightness change per grain id
float grain_variation(int32_t id) {
  uint32_t h = static_cast<uint32_t>(id) * 2654435761u;
  h ^= h >> 15;
  h *= 2246822519u;
  h ^= h >> 13;
  return 1.0f + 0.12f * ((h & 0xffff) / 65535.0f - 0.5f);
}

Vec3 rotate_to_camera(const Camera& c, const Vec3& w) {
  return {dot(w, c.right), dot(w, c.up), dot(w, c.forward)};
}

// A plane collider's ground patch, in the plane's local frame (y = 0, x and z on the plane).
struct GroundPatch {
  int k = 0;                       // collider index
  Vec3 n_c, o_c;                   // normal and a point, camera space
  float cx = 0, cz = 0, half = 2;  // patch centre and half-width, local units
  float spacing = 0.5f;            // grid spacing, local units
};

GroundPatch make_patch(int k, const ColliderState& col, const Camera& c, const Bounds& scene) {
  GroundPatch g;
  g.k = k;
  g.n_c = rotate_to_camera(c, col.pose.rotate({0, 1, 0}));
  g.o_c = c.to_camera(col.pose.t);
  if (scene.valid()) {
    float x0 = 1e30f, x1 = -1e30f, z0 = 1e30f, z1 = -1e30f;
    for (int i = 0; i < 8; ++i) {
      Vec3 w{(i & 1) ? scene.hi.x : scene.lo.x, (i & 2) ? scene.hi.y : scene.lo.y,
             (i & 4) ? scene.hi.z : scene.lo.z};
      Vec3 l = col.pose.inverse(w);
      x0 = std::min(x0, l.x);
      x1 = std::max(x1, l.x);
      z0 = std::min(z0, l.z);
      z1 = std::max(z1, l.z);
    }
    g.cx = 0.5f * (x0 + x1);
    g.cz = 0.5f * (z0 + z1);
    float ext = std::max({x1 - x0, z1 - z0, 0.05f});
    g.half = 0.5f * ext * 1.6f + 0.05f;
  }
  // a "nice" grid step, about a tenth of the patch
  float raw = 2 * g.half / 10;
  float p10 = std::pow(10.0f, std::floor(std::log10(raw)));
  float m = raw / p10;
  g.spacing = p10 * (m < 1.5f ? 1 : (m < 3.5f ? 2 : 5));
  return g;
}

// Bounding-sphere radius of a finite collider's local shape (before the pose's scale).
float local_bound(const Shape& s) {
  switch (s.kind) {
    case ShapeKind::Box:
      return 0.5f * length(s.size);
    case ShapeKind::Sphere:
      return s.radius;
    case ShapeKind::Torus:
      return s.radius + s.tube;
    case ShapeKind::Capsule:
      return 0.5f * s.height + s.radius;
    case ShapeKind::Mesh:
      return s.mesh ? s.mesh->bound_radius() : 0.0f;
    case ShapeKind::Plane:
      break;
  }
  return 0;
}

// Draws a depth-tested, anti-aliased segment between world points a and b (radii ra, rb: the
// line shows through its own grains, whose front surfaces lie up to a radius nearer).
void draw_edge(Image& img, const Camera& cam, Vec3 a, Vec3 b, float ra, float rb, const Rgb& col,
               float width) {
  Vec3 qa = cam.to_camera(a), qb = cam.to_camera(b);
  if (qa.z < kNear && qb.z < kNear) return;
  if (qa.z < kNear) {  // clip at the near plane
    float s = (kNear - qa.z) / (qb.z - qa.z);
    qa = qa + (qb - qa) * s;
    ra += (rb - ra) * s;
  } else if (qb.z < kNear) {
    float s = (kNear - qb.z) / (qa.z - qb.z);
    qb = qb + (qa - qb) * s;
    rb += (ra - rb) * s;
  }
  // pixel coordinates with integer values at pixel centres
  float x0 = 0.5f * cam.width + cam.focal * qa.x / qa.z - 0.5f;
  float y0 = 0.5f * cam.height - cam.focal * qa.y / qa.z - 0.5f;
  float x1 = 0.5f * cam.width + cam.focal * qb.x / qb.z - 0.5f;
  float y1 = 0.5f * cam.height - cam.focal * qb.y / qb.z - 0.5f;
  float iz0 = 1 / qa.z, iz1 = 1 / qb.z;
  bool steep = std::fabs(y1 - y0) > std::fabs(x1 - x0);
  if (steep) {
    std::swap(x0, y0);
    std::swap(x1, y1);
  }
  if (x0 > x1) {
    std::swap(x0, x1);
    std::swap(y0, y1);
    std::swap(iz0, iz1);
    std::swap(ra, rb);
  }
  const float len = x1 - x0;
  const int W = steep ? img.height : img.width, H = steep ? img.width : img.height;
  int xs = std::max(0, static_cast<int>(std::ceil(x0 - 0.5f)));
  int xe = std::min(W - 1, static_cast<int>(std::floor(x1 + 0.5f)));
  const float hw = 0.5f * width;
  for (int x = xs; x <= xe; ++x) {
    float s = len > 1e-6f ? std::clamp((x - x0) / len, 0.0f, 1.0f) : 0.0f;
    float y = y0 + (y1 - y0) * s;
    float z = 1 / (iz0 + (iz1 - iz0) * s);  // perspective-correct depth
    float r = ra + (rb - ra) * s;
    // coverage of each pixel [k - 0.5, k + 0.5] by the band [y - hw, y + hw]
    int k0 = static_cast<int>(std::floor(y - hw + 0.5f)),
        k1 = static_cast<int>(std::floor(y + hw + 0.5f));
    for (int k = std::max(k0, 0); k <= std::min(k1, H - 1); ++k) {
      float cov = std::min(k + 0.5f, y + hw) - std::max(k - 0.5f, y - hw);
      if (cov <= 0) continue;
      int px = steep ? k : x, py = steep ? x : k;
      float zb = img.depth[static_cast<size_t>(py) * img.width + px];
      if (z < zb + 1.05f * r) img.blend(px, py, col, std::min(1.0f, cov) * 0.9f);
    }
  }
}

}  // namespace

void draw_caption(Image& img, const std::string& text) {
  int s = img.height >= 400 ? 2 : 1;
  img.fill_rect(0, 0, text_width(text, s) + 8 * s, text_height(s) + 8 * s, Rgb{1, 1, 1}, 0.55f);
  draw_text(img, 4 * s, 4 * s, text, Rgb{0.1f, 0.1f, 0.1f}, s);
}

Image render_frame(const ParticleStore& pts, const Camera& cam, const RenderSettings& settings,
                   const std::vector<ColliderState>& colliders) {
  return render_frame(std::vector<const ParticleStore*>{&pts}, cam, settings, colliders);
}

Image render_frame(const std::vector<const ParticleStore*>& objects, const Camera& cam,
                   const RenderSettings& settings, const std::vector<ColliderState>& colliders) {
  const int ss = std::clamp(settings.supersample, 1, 8);
  const Camera c = cam.scaled(ss);
  const int W = c.width, H = c.height;
  const size_t npix = static_cast<size_t>(W) * H;
  const bool by_attr = !settings.color_by.attribute.empty();

  // ---- grains: camera-space spheres, colours and pixel bounds --------------------------------
  size_t n = 0;
  for (const ParticleStore* o : objects) n += o->size();
  std::vector<Splat> splats(n);
  std::vector<Rgb> albedo(n);
  std::vector<std::vector<Rgb>> edge_colors(objects.size());
  {
    size_t base = 0;
    std::vector<float> values;
    for (size_t k = 0; k < objects.size(); ++k) {
      const ParticleStore& o = *objects[k];
      AttribDomain dom =
          by_attr ? attribute_values(o, settings.color_by.attribute, values) : AttribDomain::None;
      const int32_t* id = o.i_if("id");
      for (size_t i = 0; i < o.size(); ++i) {
        if (dom == AttribDomain::Point)
          albedo[base + i] = colormap(settings.color_by.t(values[i]));
        else
          albedo[base + i] =
              settings.sand * (settings.grain_variation && id ? grain_variation(id[i]) : 1.0f);
      }
      if (dom == AttribDomain::Edge) {
        edge_colors[k].resize(o.prim_count());
        for (size_t e = 0; e < o.prim_count(); ++e)
          edge_colors[k][e] = colormap(settings.color_by.t(values[e]));
      }
      const float* P = o.v3_if("P");
      const float* ps = o.f_if("pscale");
      const int64_t m = static_cast<int64_t>(o.size());
#pragma omp parallel for schedule(static)
      for (int64_t i = 0; i < m; ++i) {
        Splat& s = splats[base + i];
        Vec3 q = c.to_camera(load3(P, i));
        float r = ps ? ps[i] : 0.05f;
        if (!(r > 0) || !std::isfinite(q.x) || !std::isfinite(q.y) || !(q.z - r > kNear)) continue;
        float xl, xh, yl, yh;
        tangent_interval(q.x, q.z, r, &xl, &xh);
        tangent_interval(q.y, q.z, r, &yl, &yh);
        // pixel i is covered when its centre i + 0.5 lies in the interval; one pixel of slack
        float fx0 = 0.5f * W + c.focal * xl, fx1 = 0.5f * W + c.focal * xh;
        float fy0 = 0.5f * H - c.focal * yh, fy1 = 0.5f * H - c.focal * yl;
        if (fx1 < -1 || fy1 < -1 || fx0 > W + 1 || fy0 > H + 1) continue;
        s.c = q;
        s.r = r;
        s.c2 = dot(q, q) - r * r;
        s.x0 = std::max(0, static_cast<int>(std::floor(fx0 - 0.5f)));
        s.x1 = std::min(W - 1, static_cast<int>(std::ceil(fx1 - 0.5f)));
        s.y0 = std::max(0, static_cast<int>(std::floor(fy0 - 0.5f)));
        s.y1 = std::min(H - 1, static_cast<int>(std::ceil(fy1 - 0.5f)));
      }
      base += o.size();
    }
  }

  // ---- bin spheres into tiles: per-thread lists, each thread a contiguous index range --------
  const int tiles_x = (W + kTile - 1) / kTile, tiles_y = (H + kTile - 1) / kTile;
  const int ntiles = tiles_x * tiles_y;
  const int nthreads = omp_get_max_threads();
  std::vector<std::vector<std::vector<uint32_t>>> bins(nthreads,
                                                       std::vector<std::vector<uint32_t>>(ntiles));
  double radius_sum = 0;
  int64_t drawn = 0;
#pragma omp parallel reduction(+ : radius_sum, drawn)
  {
    auto& mine = bins[omp_get_thread_num()];
#pragma omp for schedule(static)
    for (int64_t i = 0; i < static_cast<int64_t>(n); ++i) {
      const Splat& s = splats[i];
      if (s.x0 > s.x1 || s.y0 > s.y1) continue;
      radius_sum += s.r;
      drawn += 1;
      for (int ty = s.y0 / kTile; ty <= s.y1 / kTile; ++ty)
        for (int tx = s.x0 / kTile; tx <= s.x1 / kTile; ++tx)
          mine[ty * tiles_x + tx].push_back(static_cast<uint32_t>(i));
    }
  }
  const float mean_radius = drawn > 0 ? static_cast<float>(radius_sum / drawn) : 0.0f;

  // ---- splat: nearest true sphere depth per pixel --------------------------------------------
  std::vector<float> zbuf(npix, kInf);
  std::vector<int32_t> ibuf(npix, kNone);
  std::vector<float> col_a(W), row_b(H);  // ray direction components per column / row
  for (int x = 0; x < W; ++x) col_a[x] = (x + 0.5f - 0.5f * W) / c.focal;
  for (int y = 0; y < H; ++y) row_b[y] = -(y + 0.5f - 0.5f * H) / c.focal;
#pragma omp parallel for schedule(dynamic, 4)
  for (int t = 0; t < ntiles; ++t) {
    const int tx0 = (t % tiles_x) * kTile, ty0 = (t / tiles_x) * kTile;
    const int tx1 = std::min(W, tx0 + kTile) - 1, ty1 = std::min(H, ty0 + kTile) - 1;
    for (int th = 0; th < nthreads; ++th)
      for (uint32_t idx : bins[th][t]) {
        const Splat& s = splats[idx];
        const int x0 = std::max(s.x0, tx0), x1 = std::min(s.x1, tx1);
        const int y0 = std::max(s.y0, ty0), y1 = std::min(s.y1, ty1);
        for (int y = y0; y <= y1; ++y) {
          const float b = row_b[y];
          const float bb1 = b * b + 1, bcy = b * s.c.y + s.c.z;
          float* zrow = &zbuf[static_cast<size_t>(y) * W];
          int32_t* irow = &ibuf[static_cast<size_t>(y) * W];
          for (int x = x0; x <= x1; ++x) {
            const float a = col_a[x];
            const float A = a * a + bb1, B = a * s.c.x + bcy;
            const float disc = B * B - A * s.c2;
            if (disc < 0) continue;
            const float z = (B - std::sqrt(disc)) / A;  // ray t with d.z = 1: t is the depth
            if (z < zrow[x]) {
              zrow[x] = z;
              irow[x] = static_cast<int32_t>(idx);
            }
          }
        }
      }
  }

  // ---- ground patches of plane colliders -----------------------------------------------------
  std::vector<GroundPatch> patches;
  struct Solid {
    const ColliderState* col;
    Vec3 bc;   // bounding sphere centre, camera space
    float br;  // bounding sphere radius (m)
  };
  std::vector<Solid> solids;
  for (size_t k = 0; k < colliders.size(); ++k) {
    const ColliderState& col = colliders[k];
    if (col.shape.kind == ShapeKind::Plane)
      patches.push_back(make_patch(static_cast<int>(k), col, c, settings.scene));
    else
      solids.push_back(
          {&col, c.to_camera(col.pose.t), local_bound(col.shape) * col.pose.s * 1.01f + 1e-4f});
  }
  if (!patches.empty()) {
#pragma omp parallel for schedule(static)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const size_t p = static_cast<size_t>(y) * W + x;
        const Vec3 d{col_a[x], row_b[y], 1};
        for (const GroundPatch& g : patches) {
          float denom = dot(d, g.n_c);
          if (std::fabs(denom) < 1e-9f) continue;
          float t = dot(g.o_c, g.n_c) / denom;
          if (!(t > kNear) || !(t < zbuf[p])) continue;
          Vec3 l = colliders[g.k].pose.inverse(c.to_world(d * t));
          if (std::fabs(l.x - g.cx) > g.half || std::fabs(l.z - g.cz) > g.half) continue;
          zbuf[p] = t;
          ibuf[p] = -2 - g.k;
        }
      }
  }

  // ---- shading -------------------------------------------------------------------------------
  // lights in camera space (x right, y up, z away from the viewer): key from the upper left,
  // a weak fill from the right
  const Vec3 key = normalized(Vec3{-0.45f, 0.75f, -0.5f});
  const Vec3 fill = normalized(Vec3{0.7f, 0.1f, -0.45f});
  const Rgb bg_top{0.90f, 0.90f, 0.91f}, bg_bottom{0.70f, 0.705f, 0.72f};
  const Rgb ground{0.80f, 0.79f, 0.76f}, grid{0.60f, 0.60f, 0.59f};
  const Rgb solid_color{0.52f, 0.62f, 0.78f};
  const bool shade = settings.shading;
  // screen-space ambient occlusion (normal-oriented, in the manner of Alchemy AO): samples
  // within two grain radii that rise above the surface's tangent plane darken it; each pixel
  // of a 4x4 block turns the sample pattern differently, and the box filter smooths the rest
  const float ao_range = 2.0f * mean_radius;
  float ao_dir[16][8][3];  // (pattern, sample) → unit offset x, y and radius fraction
  for (int j = 0; j < 16; ++j)
    for (int k = 0; k < 8; ++k) {
      float ang = static_cast<float>(M_PI) * (k / 4.0f + j / 32.0f);
      ao_dir[j][k][0] = std::cos(ang);
      ao_dir[j][k][1] = std::sin(ang);
      ao_dir[j][k][2] = 0.15f + 0.85f * (((k * 5 + j) % 8) + 0.5f) / 8.0f;
    }
  static const int kBayer4[4][4] = {{0, 8, 2, 10}, {12, 4, 14, 6}, {3, 11, 1, 9}, {15, 7, 13, 5}};
  std::vector<const GroundPatch*> patch_of(colliders.size(), nullptr);
  for (const GroundPatch& g : patches) patch_of[g.k] = &g;

  Image hi(W, H);
  hi.depth = zbuf;
#pragma omp parallel for schedule(dynamic, 8)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t p = static_cast<size_t>(y) * W + x;
      const Vec3 d{col_a[x], row_b[y], 1};
      const float z = zbuf[p];
      const int32_t id = ibuf[p];
      Rgb out = mix(bg_top, bg_bottom, (y + 0.5f) / H);
      const Vec3 pos = d * z;  // camera space
      Vec3 nrm{0, 0, -1};
      if (id >= 0) {
        nrm = (pos - splats[id].c) / splats[id].r;
      } else if (id <= -2) {
        nrm = patch_of[-2 - id]->n_c;
        if (dot(nrm, d) > 0) nrm = -nrm;
      }

      float ao = 1;
      if (shade && id != kNone && ao_range > 0) {
        const float rpx = std::clamp(c.focal * ao_range / z, 1.0f, 24.0f * ss);
        const auto& pat = ao_dir[kBayer4[y & 3][x & 3]];
        float occ = 0;
        for (int k = 0; k < 8; ++k) {
          float rr = rpx * pat[k][2];
          int sx = std::clamp(x + static_cast<int>(std::lround(pat[k][0] * rr)), 0, W - 1);
          int sy = std::clamp(y + static_cast<int>(std::lround(pat[k][1] * rr)), 0, H - 1);
          size_t q = static_cast<size_t>(sy) * W + sx;
          if (ibuf[q] == id || ibuf[q] == kNone) continue;  // convex: no self-occlusion
          Vec3 v = Vec3{col_a[sx], row_b[sy], 1} * zbuf[q] - pos;
          float dist2 = dot(v, v);
          float fall = 1 - dist2 / (4 * ao_range * ao_range);
          if (fall <= 0) continue;
          occ += std::max(0.0f, dot(nrm, v) / std::sqrt(dist2 + 1e-12f) - 0.1f) * fall;
        }
        ao = std::clamp(1 - 1.4f * occ / 8, 0.25f, 1.0f);
      }

      if (id >= 0) {
        const Rgb& alb = albedo[id];
        if (!shade) {
          out = alb;
        } else {
          Vec3 v = normalized(-pos);
          float ndl = std::max(0.0f, dot(nrm, key));
          float ndf = std::max(0.0f, dot(nrm, fill));
          float ndv = std::max(0.0f, dot(nrm, v));
          float amb = 0.30f + 0.12f * nrm.y;
          float rim = 0.72f + 0.28f * ndv;  // silhouettes a little darker
          float spec = std::pow(std::max(0.0f, dot(nrm, normalized(key + v))), 40.0f) * 0.10f;
          float light = (0.72f * ndl + 0.18f * ndf + amb * ao) * rim * (0.6f + 0.4f * ao);
          out = alb * light + Rgb{spec, spec, spec};
        }
      } else if (id <= -2) {
        const int k = -2 - id;
        const GroundPatch* g = patch_of[k];
        const ColliderState& col = colliders[k];
        Vec3 l = col.pose.inverse(c.to_world(d * z));
        // grid lines, anti-aliased by the pixel's footprint on the plane
        Vec3 n = nrm;
        float facing = std::fabs(dot(normalized(d), n));
        float foot = z * length(d) / c.focal / std::max(0.15f, facing) / col.pose.s;
        float u = (l.x - g->cx) / g->spacing, w = (l.z - g->cz) / g->spacing;
        float du = std::fabs(u - std::round(u)) * g->spacing,
              dw = std::fabs(w - std::round(w)) * g->spacing;
        float line_w = 0.04f * g->spacing;
        float ink = std::max(1 - smoothstep(line_w, line_w + foot, du),
                             1 - smoothstep(line_w, line_w + foot, dw));
        ink *= std::clamp(1.5f * g->spacing / std::max(foot, 1e-9f) / 8, 0.0f,
                          1.0f);  // fade dense grids
        Rgb base = mix(ground, grid, 0.7f * ink);
        if (shade) {
          float light = 0.7f + 0.3f * std::max(0.0f, dot(n, key));
          base = base * (light * ao);
        }
        // fade into the background over the patch's outer 15%
        float edge = std::max(std::fabs(l.x - g->cx), std::fabs(l.z - g->cz)) / g->half;
        out = mix(base, out, smoothstep(0.85f, 1.0f, edge));
      }

      // finite colliders: sphere-trace up to the opaque depth, laid over translucently
      if (!solids.empty()) {
        const float dlen = length(d);
        float best_t = z;
        Vec3 best_n;
        bool hit = false;
        for (const Solid& so : solids) {
          // ray vs bounding sphere
          float A = dot(d, d), B = dot(d, so.bc), C = dot(so.bc, so.bc) - so.br * so.br;
          float disc = B * B - A * C;
          if (disc < 0) continue;
          float sq = std::sqrt(disc);
          float t0 = std::max((B - sq) / A, kNear), t1 = std::min((B + sq) / A, best_t);
          if (t0 >= t1) continue;
          float t = t0;
          Vec3 wp = c.to_world(d * t);
          float dist = so.col->distance(wp, nullptr);
          if (dist < 0) continue;  // the eye is inside this collider: skip it
          for (int it = 0; it < 160 && t < t1; ++it) {
            float eps = std::max(1e-6f, 0.25f * t * dlen / c.focal);
            if (dist < eps) {
              Vec3 nw;
              so.col->distance(wp, &nw);
              best_t = t;
              best_n = rotate_to_camera(c, nw);
              hit = true;
              break;
            }
            t += dist / dlen;
            wp = c.to_world(d * t);
            dist = so.col->distance(wp, nullptr);
          }
        }
        if (hit) {
          Vec3 v = normalized(-d);
          float ndv = std::fabs(dot(best_n, v));
          Rgb sc = solid_color;
          if (shade) {
            float ndl = std::max(0.0f, dot(best_n, key));
            float spec = std::pow(std::max(0.0f, dot(best_n, normalized(key + v))), 30.0f) * 0.25f;
            sc = sc * (0.45f + 0.55f * ndl) + Rgb{spec, spec, spec};
          }
          float alpha = shade ? 0.45f + 0.4f * (1 - ndv) : 1.0f;  // denser at grazing angles
          out = mix(out, sc, alpha);
        }
      }
      hi.set(x, y, out);
    }

  // ---- down to the camera's size; edges and overlays at full resolution ----------------------
  Image img = downscale(hi, ss);
  if (settings.draw_edges) {
    for (size_t k = 0; k < objects.size(); ++k) {
      const ParticleStore& o = *objects[k];
      const auto& prims = o.prim_points();
      const float* P = o.v3_if("P");
      const float* ps = o.f_if("pscale");
      for (size_t e = 0; e < o.prim_count(); ++e) {
        int32_t a = prims[2 * e], b = prims[2 * e + 1];
        if (a < 0 || b < 0 || static_cast<size_t>(a) >= o.size() ||
            static_cast<size_t>(b) >= o.size())
          continue;
        const Rgb& ec = edge_colors[k].empty() ? settings.edge_color : edge_colors[k][e];
        draw_edge(img, cam, load3(P, a), load3(P, b), ps ? ps[a] : 0, ps ? ps[b] : 0, ec,
                  settings.edge_width);
      }
    }
  }
  if (!settings.caption.empty()) draw_caption(img, settings.caption);
  if (by_attr && settings.color_bar) draw_color_bar(img, settings.color_by);
  return img;
}

}  // namespace grains::viewer
