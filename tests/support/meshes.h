// Triangle meshes for collider tests: a box (closed, outward), a subdivided icosahedron
// (closed, its vertices on the sphere) and a flat quad (an open sheet).
#pragma once
#include <array>
#include <cmath>
#include <map>
#include <utility>

#include "engine/geometry_io.h"

namespace grains::test {

// The box centred at c with full extents `size`, 12 triangles wound outward; `split` gives every
// face its own four vertices (24 in all), as exporters that split seams write it.
inline Mesh box_mesh(const Vec3& c, const Vec3& size, bool split = false) {
  Mesh m;
  const Vec3 h = size * 0.5f;
  // each face: outward axis a with sign s; its corners in counter-clockwise order seen from outside
  for (int a = 0; a < 3; ++a)
    for (int s : {-1, 1}) {
      const int u = (a + 1) % 3, w = (a + 2) % 3;
      int base = static_cast<int>(m.vertices.size());
      const float du[4] = {-1, 1, 1, -1}, dw[4] = {-1, -1, 1, 1};
      for (int k = 0; k < 4; ++k) {
        Vec3 p = c;
        p[a] += s * h[a];
        p[u] += du[k] * h[u];
        p[w] += dw[k] * h[w];
        m.vertices.push_back(p);
      }
      // (u, w, a) is right-handed, so u-then-w counter-clockwise faces +a
      if (s > 0) {
        m.triangles.push_back({base, base + 1, base + 2});
        m.triangles.push_back({base, base + 2, base + 3});
      } else {
        m.triangles.push_back({base, base + 2, base + 1});
        m.triangles.push_back({base, base + 3, base + 2});
      }
    }
  if (split) return m;
  // weld: one vertex per corner
  Mesh welded;
  std::map<std::array<float, 3>, int> index;
  std::vector<int> remap;
  for (const Vec3& p : m.vertices) {
    auto [it, fresh] = index.insert({{p.x, p.y, p.z}, static_cast<int>(welded.vertices.size())});
    if (fresh) welded.vertices.push_back(p);
    remap.push_back(it->second);
  }
  for (const auto& t : m.triangles) welded.triangles.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
  return welded;
}

// A sphere of radius r at c: an icosahedron subdivided `levels` times, vertices on the sphere.
inline Mesh sphere_mesh(const Vec3& c, float r, int levels) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Vec3> v = {{-1, t, 0}, {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3& p : v) p = normalized(p);
  std::vector<std::array<int, 3>> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                       {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                       {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                       {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto middle = [&](int a, int b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back(normalized(v[a] + v[b]));
      return mid[key] = static_cast<int>(v.size()) - 1;
    };
    std::vector<std::array<int, 3>> g;
    for (const auto& tri : f) {
      int ab = middle(tri[0], tri[1]), bc = middle(tri[1], tri[2]), ca = middle(tri[2], tri[0]);
      g.push_back({tri[0], ab, ca});
      g.push_back({tri[1], bc, ab});
      g.push_back({tri[2], ca, bc});
      g.push_back({ab, bc, ca});
    }
    f = std::move(g);
  }
  Mesh m;
  for (const Vec3& p : v) m.vertices.push_back(c + p * r);
  m.triangles = f;
  return m;
}

// The square sheet y = y0, |x|, |z| <= half: two triangles, normal +y, open.
inline Mesh quad_mesh(float half, float y0 = 0.0f) {
  Mesh m;
  m.vertices = {{-half, y0, -half}, {half, y0, -half}, {half, y0, half}, {-half, y0, half}};
  m.triangles = {{0, 2, 1}, {0, 3, 2}};
  return m;
}

}  // namespace grains::test
