// source: a stream generator. Fills a box, sphere or grid at `separation` (grid or hexagonal
// packing, optional jitter), reads points from a PLY/OBJ file, turns an image mask into a flat
// sheet, scatters grains over a triangle mesh's surface or fills its inside; emits once at a
// frame or at a rate over a frame range, with an initial velocity. pscale
// defaults to separation/2 and mass comes from density when one is given. With connect_radius,
// each emission's grains are joined by explicit constraints (2-point primitives) to the grains
// of the same emission within connect_radius x separation.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <unordered_map>

#define STB_IMAGE_IMPLEMENTATION
#include <stb_image.h>

#include "engine/geometry_io.h"
#include "engine/mesh_shape.h"
#include "engine/node.h"
#include "engine/param_rows.h"
#include "engine/simulation.h"
#include "engine/state_stream.h"
#include "nodes/common.h"
#include "nodes/register.h"

namespace grains {
namespace {

// a grain count for a message: whole below 1e15, else in powers of ten
std::string count_text(double n) {
  char buf[32];
  std::snprintf(buf, sizeof buf, n < 1e15 ? "%.0f" : "%.3g", n);
  return buf;
}

// the menus' choices, in their order
enum Shape { kBox, kSphere, kGrid, kFile, kImage, kSurface, kVolume };
enum Emission { kOnce, kRate };
enum Packing { kCubic, kHexagonal };

// the node's parameters (engine/param_rows.h)
#define SOURCE_PARAMS(ROW)                                                                          \
  ROW(FLOAT, activation, 1, , "the node emits only while this is greater than 0")                  \
  ROW(MENU, shape, kBox,                                                                            \
      .menu_of({"box", "sphere", "grid", "file", "image", "surface", "volume"}),                    \
      "what to fill: a box, a sphere, a one-layer grid in the xz plane, the points of `file`, a "  \
      "sheet in the xz plane (size x, z) from the PNG mask `file`, the surface of the mesh `file` " \
      "(grains on it, no two closer than the separation), or the inside of the closed mesh `file` " \
      "(the packing, grains wholly inside)")                                                         \
  ROW(VECTOR, center, (0, 0, 0), .unit("m"), "centre of the shape; offset added to file points")   \
  ROW(VECTOR, size, (1, 1, 1), .unit("m"), "full extents of the box or grid")                       \
  ROW(FLOAT, radius, 0.5, .positive().unit("m"), "radius of the sphere")                            \
  ROW(STRING, file, "", ,                                                                           \
      "PLY or OBJ file of points (shape \"file\"), PLY or OBJ triangle mesh (\"surface\", "          \
      "\"volume\") or PNG mask (\"image\"), relative to the graph")                                     \
  ROW(FLOAT, threshold, 0.5, .range(0, 1),                                                          \
      "image: a grain where the pixel block's alpha (or luminance) exceeds this")                   \
  ROW(FLOAT, connect_radius, 0, .at_least(0),                                                       \
      "connect each new grain to those of the same emission within this times the separation "     \
      "(0: none; image: 1.5, edges and diagonals)")                                                 \
  ROW(FLOAT, separation, 0.1, .positive().unit("m"), "distance between neighbouring grains")        \
  ROW(MENU, packing, kCubic, .menu_of({"grid", "hexagonal"}), "cubic grid or hexagonal close packing") \
  ROW(FLOAT, jitter, 0, .range(0, 1), "random offset of each grain, as a fraction of the separation") \
  ROW(MENU, emission, kOnce, .menu_of({"once", "rate"}),                                            \
      "emit the whole fill once at `birth_frame`, or random points at `rate`: in the box, sphere, " \
      "grid, on the mesh's surface or inside it, or picked among the file's points or the mask's " \
      "sheet")                                                                                      \
  ROW(INT, birth_frame, 1, .at_least(1), "frame of the one-time emission")                          \
  ROW(FLOAT, rate, 100, .at_least(0).unit("1/s"), "grains per second while emitting at a rate")     \
  ROW(INT, start_frame, 1, .at_least(1), "first frame of rate emission")                            \
  ROW(INT, end_frame, 1000000, .at_least(1), "last frame of rate emission")                         \
  ROW(VECTOR, velocity, (0, 0, 0), .unit("m/s"), "initial velocity")                                \
  ROW(FLOAT, pscale, 0, .at_least(0).unit("m"), "grain radius; 0 means separation/2")               \
  ROW(FLOAT, density, 0, .at_least(0).unit("kg/m^3"),                                               \
      "mass = density * 4/3 pi pscale^3 when greater than 0")                                       \
  ROW(FLOAT, mass, 1, .positive().unit("kg"), "mass of each grain when density is 0")               \
  ROW(STRING, group, "", , "also put the new grains in this group")
GR_NODE_PARAMS(SourceParams, SOURCE_PARAMS)

class SourceNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    p_ = SourceParams::read(ctx.params);
    const SourceParams& p = p_;
    if (p.activation <= 0) return;
    if (p.emission == kOnce) {
      if (emitted_ || ctx.time.frame != p.birth_frame || ctx.time.substep != 0) return;
      emitted_ = true;
      std::vector<Vec3> pts = fill(ctx);
      size_t first = ctx.pts.size();
      emit(ctx, pts);
      if (p.shape == kFile) copy_file_attributes(ctx, first);
      connect(ctx, first);
    } else {  // rate
      int f = ctx.time.frame;
      if (f < p.start_frame || f > p.end_frame) return;
      // what the frame will have emitted at this rate by its end, checked at its first substep:
      // a rate far over the budget would otherwise fill it a substep at a time, slowly
      if (ctx.time.substep == 0)
        check_point_budget(ctx.node_name, std::floor(carry_ + p.rate / ctx.time.fps),
                           ctx.pts.size(), ctx.max_points,
                           "emitting " + count_text(p.rate) + " grains a second for a frame");
      carry_ += p.rate * ctx.time.dt;
      check_point_budget(ctx.node_name, std::floor(carry_), ctx.pts.size(), ctx.max_points,
                         "emitting " + count_text(p.rate) + " grains a second");
      int count = static_cast<int>(std::floor(carry_));
      carry_ -= count;
      std::vector<Vec3> pts;
      std::vector<uint32_t> picks;
      if (p.shape == kFile || p.shape == kImage) {
        // random points of the file or of the mask's sheet, as POP Source emits from a
        // geometry's points at a rate: each pick uniform among them, with replacement
        const std::vector<Vec3>& from = shape_points(ctx);
        const Vec3 c = p.center;
        for (int k = 0; k < count && !from.empty(); ++k) {
          const float u = rand01(ctx.seed, 3 * counter_++);
          const uint32_t pick =
              std::min(static_cast<uint32_t>(from.size() - 1), static_cast<uint32_t>(u * from.size()));
          picks.push_back(pick);
          pts.push_back(from[pick] + c);
        }
      } else {
        for (int k = 0; k < count; ++k) pts.push_back(random_point(ctx));
      }
      size_t first = ctx.pts.size();
      emit(ctx, pts);
      if (p.shape == kFile && !pts.empty()) copy_file_attributes(ctx, first, &picks);
      connect(ctx, first);
    }
  }

  // the emission clock: whether a `once` source has emitted, the part of a grain a `rate`
  // source owes, the random draws taken (file_ and shape_pts_ are inputs read again, not state)
  void save_state(StateWriter& w) const override {
    w.section("source");
    w.value(emitted_);
    w.value(carry_);
    w.value(counter_);
  }
  void load_state(StateReader& r) override {
    r.section("source");
    r.value(emitted_);
    r.value(carry_);
    r.value(counter_);
  }

 private:
  // Points filling the shape at the separation; grid or hexagonal close packing.
  std::vector<Vec3> fill(CookContext& ctx) {
    const SourceParams& p = p_;
    const int shape = p.shape;
    Vec3 c = p.center;
    std::vector<Vec3> out;
    if (shape == kFile) {
      file_ = read_ply_or_obj(ctx);
      check_point_budget(ctx.node_name, double(file_.size()), ctx.pts.size(), ctx.max_points,
                         "the file's " + std::to_string(file_.size()) + " points");
      const float* P = file_.v3_if("P");
      for (size_t k = 0; k < file_.size(); ++k) out.push_back(load3(P, k) + c);
      return out;
    }
    float s = static_cast<float>(p.separation);
    Vec3 size = p.size;
    if (shape == kImage) return image_sheet(ctx, c, size, s);
    if (shape == kSurface) return surface_scatter(ctx, *mesh(ctx), c, s);
    float radius = static_cast<float>(p.radius);
    bool hex = p.packing == kHexagonal;
    if (shape == kSphere) size = Vec3{2 * radius, 2 * radius, 2 * radius};
    if (shape == kGrid) size.y = 0;  // a single layer in the xz plane
    // a mesh's inside: the packing over its bounding box (one more point each way, to cover
    // it), keeping the grains wholly inside
    std::shared_ptr<const MeshShape> solid = shape == kVolume ? mesh(ctx) : nullptr;
    const bool cover = shape == kGrid || shape == kVolume;
    if (solid) {
      size = solid->upper() - solid->lower();
      c = p.center + (solid->upper() + solid->lower()) * 0.5f;
    }
    // hexagonal close packing: rows offset by s/2, layers by s*sqrt(3)/2 and sqrt(2/3)*s
    float dx = s, dz = hex ? s * std::sqrt(3.0f) / 2 : s, dy = hex ? s * std::sqrt(2.0f / 3.0f) : s;
    // counts along each axis, checked against the point budget before any is made
    const double cx = std::max(1.0, double(std::floor(size.x / dx + 1e-4f)) + (cover ? 1 : 0));
    const double cy = shape == kGrid ? 1.0
                                     : std::max(1.0, double(std::floor(size.y / dy + 1e-4f)) +
                                                         (shape == kVolume ? 1 : 0));
    const double cz = std::max(1.0, double(std::floor(size.z / dz + 1e-4f)) + (cover ? 1 : 0));
    check_point_budget(ctx.node_name, cx * cy * cz, ctx.pts.size(), ctx.max_points,
                       "a " + p.shape.text + " of " + count_text(cx) + " x " + count_text(cy) + " x " +
                           count_text(cz) + " grains");
    const int nx = static_cast<int>(cx), ny = static_cast<int>(cy), nz = static_cast<int>(cz);
    Vec3 lo = c - Vec3{(nx - 1) * dx, (ny - 1) * dy, (nz - 1) * dz} * 0.5f;
    float jitter = static_cast<float>(p.jitter) * s;
    uint64_t counter = 0;
    // a box's hexagonal rows and layers stay within the square lattice's extent: an offset
    // row ends half a separation short, an offset layer a row short (its rows stand s / sqrt(12)
    // over the others'), so that every grain lies wholly inside the box (a sleeve around it is
    // not entered)
    const Vec3 hi = c + Vec3{(nx - 1) * dx, (ny - 1) * dy, (nz - 1) * dz} * 0.5f;
    const bool clip = hex && shape == kBox;
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k)
        for (int i = 0; i < nx; ++i) {
          Vec3 q = lo + Vec3{i * dx, j * dy, k * dz};
          if (hex) {
            q.x += ((j + k) % 2) * s * 0.5f;
            q.z += (j % 2) * s * std::sqrt(3.0f) / 6;
            if (clip && (q.x > hi.x + 1e-4f * s || q.z > hi.z + 1e-4f * s)) {
              counter += 3;
              continue;
            }
          }
          if (jitter > 0) {
            q += Vec3{rand01(ctx.seed, counter) - 0.5f, rand01(ctx.seed, counter + 1) - 0.5f,
                      rand01(ctx.seed, counter + 2) - 0.5f} * jitter;
          }
          counter += 3;
          if (shape == kSphere && length(q - c) > radius) continue;
          if (solid && solid->distance(q - p.center, nullptr, grain_radius()) > -grain_radius())
            continue;
          out.push_back(q);
        }
    return out;
  }

  float grain_radius() const {
    return p_.pscale > 0 ? static_cast<float>(p_.pscale) : static_cast<float>(p_.separation) * 0.5f;
  }

  std::shared_ptr<const MeshShape> mesh(CookContext& ctx) const {
    return cached_mesh_shape(resolve_path(ctx.base_dir, p_.file));
  }

  // The running sum of the mesh's triangle areas (the last is the whole area), for picking a
  // point uniformly over the surface.
  static std::vector<double> cumulative_areas(const Mesh& m) {
    std::vector<double> sum;
    double total = 0;
    for (const auto& t : m.triangles) {
      total += 0.5 * double(length(cross(m.vertices[t[1]] - m.vertices[t[0]],
                                         m.vertices[t[2]] - m.vertices[t[0]])));
      sum.push_back(total);
    }
    return sum;
  }

  // A point uniform over the surface from three uniform numbers: a triangle by area, then a
  // point uniform in it (the square-root warp of the barycentric coordinates).
  static Vec3 surface_point(const Mesh& m, const std::vector<double>& areas, float u0, float u1,
                            float u2) {
    const double at = u0 * areas.back();
    size_t t = std::upper_bound(areas.begin(), areas.end(), at) - areas.begin();
    t = std::min(t, areas.size() - 1);
    const auto& tri = m.triangles[t];
    const float a = std::sqrt(u1);
    return m.vertices[tri[0]] * (1 - a) + m.vertices[tri[1]] * (a * (1 - u2)) +
           m.vertices[tri[2]] * (a * u2);
  }

  // Grains on the mesh's surface (offset by c), no two closer than the separation s: random
  // points uniform over the surface, each kept when no kept point lies within s (a hash grid of
  // cell s), until 1024 in a row are refused. That leaves little room for another: on a sphere
  // it keeps 0.61 grains per s^2, 88% of the 0.70 where random sequential adding jams, and no
  // such set holds more than hexagonal packing's 1.15 (the budget is checked against that).
  std::vector<Vec3> surface_scatter(CookContext& ctx, const MeshShape& shape, const Vec3& c,
                                    float s) {
    const Mesh& m = shape.mesh();
    const std::vector<double> areas = cumulative_areas(m);
    const double most = 2.0 * areas.back() / (std::sqrt(3.0) * double(s) * double(s)) + 1;
    check_point_budget(ctx.node_name, most, ctx.pts.size(), ctx.max_points,
                       "up to " + count_text(std::floor(most)) + " grains on the surface");
    auto cell = [&](float x) {
      return static_cast<int64_t>(std::clamp(std::floor(double(x) / s), -1e15, 1e15));
    };
    auto key = [](int64_t x, int64_t y, int64_t z) {
      return static_cast<int64_t>((uint64_t(x) * 73856093u) ^ (uint64_t(y) * 19349663u) ^
                                  (uint64_t(z) * 83492791u));
    };
    std::unordered_map<int64_t, std::vector<uint32_t>> grid;
    std::vector<Vec3> kept;
    uint64_t counter = 0;
    for (int refused = 0; refused < 1024;) {
      const Vec3 q = surface_point(m, areas, rand01(ctx.seed, counter), rand01(ctx.seed, counter + 1),
                                   rand01(ctx.seed, counter + 2));
      counter += 3;
      const int64_t x = cell(q.x), y = cell(q.y), z = cell(q.z);
      bool free = true;
      for (int64_t dz = -1; dz <= 1 && free; ++dz)
        for (int64_t dy = -1; dy <= 1 && free; ++dy)
          for (int64_t dx = -1; dx <= 1 && free; ++dx) {
            auto it = grid.find(key(x + dx, y + dy, z + dz));
            if (it == grid.end()) continue;
            for (uint32_t j : it->second)
              if (length(kept[j] - q) < s) {
                free = false;
                break;
              }
          }
      if (!free) {
        ++refused;
        continue;
      }
      refused = 0;
      grid[key(x, y, z)].push_back(static_cast<uint32_t>(kept.size()));
      kept.push_back(q);
    }
    for (Vec3& q : kept) q += c;
    return kept;
  }

  // An image mask as a flat sheet in the xz plane, size.x by size.z centred at c: one grain per
  // block of pixels at the separation (a grid like the `grid` shape), kept where the block's
  // mean alpha, or luminance without an alpha channel, in [0, 1], exceeds `threshold`. Image
  // rows run along +z, columns along +x (viewed from above with +z down the page it reads
  // upright).
  std::vector<Vec3> image_sheet(CookContext& ctx, const Vec3& c, const Vec3& size, float s) {
    std::string path = resolve_path(ctx.base_dir, p_.file);
    int w = 0, h = 0, channels = 0;
    if (std::string bad = input_file_problem(path, kMaxGeometryFileBytes); !bad.empty())
      throw GeometryError(path + ": " + bad);
    unsigned char* img = stbi_load(path.c_str(), &w, &h, &channels, 0);
    if (!img)
      throw GeometryError(path + ": not an image the source can read (" + stbi_failure_reason() + ")");
    auto coverage = [&](int x, int y) {
      const unsigned char* px = img + (static_cast<size_t>(y) * w + x) * channels;
      if (channels == 2 || channels == 4) return px[channels - 1] / 255.0f;
      if (channels == 1) return px[0] / 255.0f;
      return (0.299f * px[0] + 0.587f * px[1] + 0.114f * px[2]) / 255.0f;
    };
    const double cx = std::max(1.0, double(std::floor(size.x / s + 1e-4f)) + 1);
    const double cz = std::max(1.0, double(std::floor(size.z / s + 1e-4f)) + 1);
    check_point_budget(ctx.node_name, cx * cz, ctx.pts.size(), ctx.max_points,
                       "an image sheet of " + count_text(cx) + " x " + count_text(cz) + " grains");
    const int nx = static_cast<int>(cx), nz = static_cast<int>(cz);
    Vec3 lo = c - Vec3{(nx - 1) * s, 0, (nz - 1) * s} * 0.5f;
    float threshold = static_cast<float>(p_.threshold);
    std::vector<Vec3> out;
    for (int k = 0; k < nz; ++k)
      for (int i = 0; i < nx; ++i) {
        // the block of pixels this grain covers (at least one pixel)
        int x0 = i * w / nx, x1 = std::max(x0 + 1, (i + 1) * w / nx);
        int y0 = k * h / nz, y1 = std::max(y0 + 1, (k + 1) * h / nz);
        double sum = 0;
        for (int y = y0; y < y1; ++y)
          for (int x = x0; x < x1; ++x) sum += coverage(x, y);
        if (sum / ((x1 - x0) * (y1 - y0)) > threshold) out.push_back(lo + Vec3{i * s, 0, k * s});
      }
    stbi_image_free(img);
    return out;
  }

  // Explicit constraints between the grains of one emission (points first..end) closer than
  // connect_radius x separation: restlength = the distance at birth, strength 1, strain 0. A
  // hash grid of that cell size finds the pairs; each pair once, in a fixed order.
  void connect(CookContext& ctx, size_t first) {
    const SourceParams& p = p_;
    float factor = static_cast<float>(p.connect_radius);
    if (factor == 0 && p.shape == kImage) factor = 1.5f;  // image sheets come connected
    ParticleStore& s = ctx.pts;
    const size_t end = s.size();
    float R = factor * static_cast<float>(p.separation);
    if (!(R > 0) || end - first < 2) return;
    const float* P = s.v3("P");
    // clamped before the cast and hashed unsigned: a tiny connect_radius makes x / R overflow
    // int64 and the hash products overflow (both undefined; UBSan in the catalogue's
    // crash_connect_radius_1e_30); the clamped cells only cost a longer search
    auto cell = [&](float c) {
      return static_cast<int64_t>(std::clamp(std::floor(double(c) / R), -1e15, 1e15));
    };
    auto cell_of = [&](const Vec3& x) {
      return std::array<int64_t, 3>{cell(x.x), cell(x.y), cell(x.z)};
    };
    auto key = [](int64_t x, int64_t y, int64_t z) {
      return static_cast<int64_t>((uint64_t(x) * 73856093u) ^ (uint64_t(y) * 19349663u) ^
                                  (uint64_t(z) * 83492791u));
    };
    std::unordered_map<int64_t, std::vector<uint32_t>> grid;
    for (size_t i = first; i < end; ++i) {
      auto q = cell_of(load3(P, i));
      grid[key(q[0], q[1], q[2])].push_back(static_cast<uint32_t>(i));
    }
    std::vector<std::pair<uint32_t, uint32_t>> pairs;
    // constraints count against the point budget at a tenth of a point each (about 60 of a
    // point's 600 bytes): a connect_radius of many separations joins every pair, N^2 / 2
    const double most = double(ctx.max_points) * 10.0;
    for (size_t i = first; i < end; ++i) {
      if (double(s.prim_count() + pairs.size()) > most) {
        char buf[300];
        std::snprintf(buf, sizeof buf,
                      "node '%s': connect_radius %g joins more than %.4g pairs of its %zu grains, "
                      "over the budget of %zu points (a constraint counts a tenth of a point); "
                      "raise it with --max-points",
                      ctx.node_name.c_str(), p.connect_radius, most, end - first, ctx.max_points);
        throw BudgetError(buf);
      }
      Vec3 xi = load3(P, i);
      auto q = cell_of(xi);
      size_t row = pairs.size();
      for (int64_t dz = -1; dz <= 1; ++dz)
        for (int64_t dy = -1; dy <= 1; ++dy)
          for (int64_t dx = -1; dx <= 1; ++dx) {
            auto it = grid.find(key(q[0] + dx, q[1] + dy, q[2] + dz));
            if (it == grid.end()) continue;
            for (uint32_t j : it->second) {
              if (j <= i) continue;
              float dist = length(load3(P, j) - xi);
              if (dist < R) pairs.push_back({static_cast<uint32_t>(i), j});
            }
          }
      // hash collisions may list a cell twice: keep each pair once, in order of j
      std::sort(pairs.begin() + row, pairs.end());
      pairs.erase(std::unique(pairs.begin() + row, pairs.end()), pairs.end());
    }
    for (auto [a, b] : pairs) {
      size_t q = s.add_prim(static_cast<int32_t>(a), static_cast<int32_t>(b));
      s.prim_f("restlength")[q] = length(load3(P, a) - load3(P, b));
      s.prim_f("strength")[q] = 1.0f;
    }
  }

  Vec3 random_point(CookContext& ctx) {
    const SourceParams& p = p_;
    Vec3 c = p.center;
    uint64_t k = 3 * counter_++;
    Vec3 u{rand01(ctx.seed, k), rand01(ctx.seed, k + 1), rand01(ctx.seed, k + 2)};
    if (p.shape == kSphere) {  // uniform in the ball by rejection-free radius scaling
      float r = static_cast<float>(p.radius) * std::cbrt(u.x);
      float z = 2 * u.y - 1, phi = 2 * static_cast<float>(M_PI) * u.z;
      float q = std::sqrt(std::max(0.0f, 1 - z * z));
      return c + Vec3{q * std::cos(phi), z, q * std::sin(phi)} * r;
    }
    if (p.shape == kSurface) {
      const std::shared_ptr<const MeshShape> m = mesh(ctx);
      if (m != rate_mesh_) {
        rate_mesh_ = m;
        rate_areas_ = cumulative_areas(m->mesh());
      }
      return c + surface_point(m->mesh(), rate_areas_, u.x, u.y, u.z);
    }
    if (p.shape == kVolume) {  // uniform in the bounding box, kept wholly inside
      const std::shared_ptr<const MeshShape> m = mesh(ctx);
      const Vec3 lo = m->lower(), ext = m->upper() - m->lower();
      const float r = grain_radius();
      for (int tries = 0; tries < 100000; ++tries) {
        const Vec3 q = lo + Vec3{u.x * ext.x, u.y * ext.y, u.z * ext.z};
        if (m->distance(q, nullptr, r) <= -r) return c + q;
        k = 3 * counter_++;
        u = {rand01(ctx.seed, k), rand01(ctx.seed, k + 1), rand01(ctx.seed, k + 2)};
      }
      throw GeometryError(resolve_path(ctx.base_dir, p.file) + ": no grain of radius " +
                          std::to_string(r) +
                          " m fits inside the mesh (100000 random points of its bounding box "
                          "tried)");
    }
    Vec3 size = p.size;
    if (p.shape == kGrid) size.y = 0;
    return c + Vec3{(u.x - 0.5f) * size.x, (u.y - 0.5f) * size.y, (u.z - 0.5f) * size.z};
  }

  // The file's points; file_attributes_ gets the point attributes it provides itself
  ParticleStore read_ply_or_obj(CookContext& ctx) {
    std::string path = resolve_path(ctx.base_dir, p_.file);
    if (std::filesystem::path(path).extension() == ".ply") return read_ply(path, &file_attributes_);
    file_attributes_ = {"P"};
    Mesh m = read_mesh(path);
    ParticleStore s;
    s.add_points(m.vertices.size());
    float* P = s.v3("P");
    for (size_t k = 0; k < m.vertices.size(); ++k) store3(P, k, m.vertices[k]);
    return s;
  }

  // The points a rate emission picks from, about the origin (the centre is added per pick, so
  // it may move): the file's points, or the mask's sheet. Read once per file and sheet size,
  // separation and threshold; a cache of the inputs, not run state (a resumed run reads them
  // again).
  const std::vector<Vec3>& shape_points(CookContext& ctx) {
    const SourceParams& p = p_;
    const std::string key = p.shape.text + "|" + resolve_path(ctx.base_dir, p.file) + "|" +
                            (p.shape == kImage ? std::to_string(p.size.x) + "," +
                                                     std::to_string(p.size.z) + "," +
                                                     std::to_string(p.separation) + "," +
                                                     std::to_string(p.threshold)
                                               : std::string());
    if (key == shape_key_) return shape_pts_;
    shape_pts_.clear();
    if (p.shape == kFile) {
      file_ = read_ply_or_obj(ctx);
      const float* P = file_.v3_if("P");
      for (size_t k = 0; k < file_.size(); ++k) shape_pts_.push_back(load3(P, k));
    } else {
      shape_pts_ = image_sheet(ctx, Vec3{0, 0, 0}, p.size, static_cast<float>(p.separation));
    }
    shape_key_ = key;
    return shape_pts_;
  }

  void emit(CookContext& ctx, const std::vector<Vec3>& pts) {
    if (pts.empty()) return;
    const SourceParams& p = p_;
    ParticleStore& s = ctx.pts;
    size_t first = s.add_points(pts.size());
    float sep = static_cast<float>(p.separation);
    float r = p.pscale > 0 ? static_cast<float>(p.pscale) : sep * 0.5f;
    float density = static_cast<float>(p.density);
    float mass = density > 0 ? density * 4.0f / 3.0f * static_cast<float>(M_PI) * r * r * r
                             : static_cast<float>(p.mass);
    Vec3 vel = p.velocity;
    const std::string& group = p.group;
    float* P = s.v3("P");
    float* v = s.v3("v");
    float* rest = s.v3("rest");
    float* ps = s.f("pscale");
    float* m = s.f("mass");
    int32_t* sid = s.i("streamid");
    for (size_t k = 0; k < pts.size(); ++k) {
      size_t i = first + k;
      store3(P, i, pts[k]);
      store3(rest, i, pts[k]);
      store3(v, i, vel);
      ps[i] = r;
      m[i] = mass;
      sid[i] = ctx.stream;
      if (!group.empty()) s.set_group(group, i, true);
    }
  }

  // The file's own point attributes (pscale, v, mass, targetP, ...) override the source's
  // parameters; those it lacks keep them (the store read_ply makes holds every standard
  // attribute, at its defaults: copying those made a file without pscale 0.05 m grains whatever
  // the separation, and one without mass ignore `mass` and `density`). Without picks the new
  // points are the file's, in order, and its edges become constraints between them; with picks
  // (a rate emission) new point k is the file's point picks[k], and edges, which join points of
  // one copy of the file, are not made.
  void copy_file_attributes(CookContext& ctx, size_t first,
                            const std::vector<uint32_t>* picks = nullptr) {
    ParticleStore& s = ctx.pts;
    const size_t count = picks ? picks->size() : file_.size();
    auto from = [&](size_t k) -> size_t { return picks ? (*picks)[k] : k; };
    for (const std::string& name : file_attributes_) {
      // the stream and per-substep state belong to this source, not the file
      if (name == "P" || name == "id" || name == "streamid" || name == "ispbd" || name == "force")
        continue;
      const Attribute& a = *file_.find(name);
      Attribute& dst = s.add(name, a.type);
      const size_t c = static_cast<size_t>(a.components());
      for (size_t k = 0; k < count; ++k) {
        if (a.type == AttribType::Int) dst.i[first + k] = a.i[from(k)];
        else
          std::copy_n(a.f.begin() + from(k) * c, c, dst.f.begin() + (first + k) * c);
      }
    }
    if (std::find(file_attributes_.begin(), file_attributes_.end(), "v") !=
        file_attributes_.end()) {  // the initial velocity adds to the file's
      Vec3 vel = p_.velocity;
      float* v = s.v3("v");
      for (size_t k = 0; k < count; ++k) store3(v, first + k, load3(v, first + k) + vel);
    }
    if (picks) return;  // the file stays for the next picks (shape_points)
    const std::vector<int32_t>& e = file_.prim_points();
    for (size_t p = 0; p < file_.prim_count(); ++p) {
      size_t q = s.add_prim(static_cast<int32_t>(first) + e[2 * p], static_cast<int32_t>(first) + e[2 * p + 1]);
      for (const auto& [name, vals] : file_.prim_attributes()) s.prim_f(name)[q] = vals[p];
    }
    file_ = ParticleStore();
  }

  SourceParams p_;  // this cook's parameters
  ParticleStore file_;
  std::vector<std::string> file_attributes_;  // the point attributes file_'s file provides
  std::string shape_key_;         // what shape_pts_ were made from
  std::vector<Vec3> shape_pts_;   // a rate emission's points to pick from (shape_points)
  std::shared_ptr<const MeshShape> rate_mesh_;  // the mesh rate_areas_ were summed for
  std::vector<double> rate_areas_;  // its cumulative triangle areas (surface rate emission)
  bool emitted_ = false;
  double carry_ = 0;
  uint64_t counter_ = 0;
};

}  // namespace

void register_source_node() {
  NodeTypeInfo t;
  t.type = "source";
  t.doc = "Emits grains: fills a shape at a separation or reads points from a file (a stream generator).";
  t.role = NodeRole::Source;
  t.params = SourceParams::decls();
  t.make = [] { return std::make_unique<SourceNode>(); };
  t.check = [](const ParamSet& params, const std::string& base) -> std::pair<std::string, std::string> {
    const SourceParams p = SourceParams::read(params);
    if (p.shape == kFile || p.shape == kImage) {
      if (p.file.empty()) return {"shape \"" + p.shape.text + "\" needs a `file`", "file"};
      std::string path = resolve_path(base, p.file);
      if (!std::filesystem::exists(path)) return {"file not found: " + path, "file"};
    }
    if (p.shape == kSurface || p.shape == kVolume) {
      if (p.file.empty()) return {"shape \"" + p.shape.text + "\" needs a mesh `file`", "file"};
      std::shared_ptr<const MeshShape> m;
      try {
        m = cached_mesh_shape(resolve_path(base, p.file));
      } catch (const GeometryError& e) {
        return {e.what(), "file"};
      }
      if (p.shape == kVolume && !m->closed())
        return {resolve_path(base, p.file) +
                    ": a volume fill needs a closed mesh (every edge shared by two triangles "
                    "running along it in opposite directions); this one is open",
                "file"};
    }
    if (!p.group.empty())
      if (std::string bad = group_name_problem(p.group); !bad.empty()) return {bad, "group"};
    // a box, sphere or grid whose grains would lie where floats cannot tell them apart (the
    // run's own check, Simulation::step_frame, stops at the first frame; exit 1): refused here
    if ((p.shape == kBox || p.shape == kSphere || p.shape == kGrid) &&
        !params.is_animated("center") && !params.is_animated("size") &&
        !params.is_animated("radius") && !params.is_animated("pscale") &&
        !params.is_animated("separation")) {
      const double c[3] = {p.center.x, p.center.y, p.center.z};
      const double size[3] = {p.size.x, p.size.y, p.size.z};
      double centre = 0, extent = 0;
      for (int k = 0; k < 3; ++k) {
        centre = std::max(centre, std::fabs(c[k]));
        extent = std::max(extent, p.shape == kSphere ? p.radius : 0.5 * std::fabs(size[k]));
      }
      const float r = p.pscale > 0 ? float(p.pscale) : 0.5f * float(p.separation);
      const double most = precise_reach(r, kCoarsestResolution);
      if (centre + extent > most) {
        char buf[300];
        std::snprintf(buf, sizeof buf,
                      "its grains would lie up to %.4g m from the origin, where floats cannot "
                      "tell grains of radius %.3g m apart; keep the shape within %.4g m of it",
                      centre + extent, r, most);
        // grains too small to place within a metre of the origin: their radius is what is wrong
        const char* blame = most < 1.0           ? (p.pscale > 0 ? "pscale" : "separation")
                            : centre >= extent   ? "center"
                            : p.shape == kSphere ? "radius"
                                                 : "size";
        return {buf, blame};
      }
    }
    return {"", ""};
  };
  // its group's attribute; a file's own point attributes are known only once it is read
  t.adds_attributes = [](const ParamSet& params) {
    const SourceParams p = SourceParams::read(params);
    std::vector<std::string> out;
    if (!p.group.empty()) out.push_back(group_attribute(p.group));
    if (p.shape == kFile) out.push_back("*");
    return out;
  };
  register_node_type(std::move(t));
}

}  // namespace grains
