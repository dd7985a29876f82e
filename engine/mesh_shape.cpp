#include "engine/mesh_shape.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>

namespace grains {
namespace {

struct D3 {
  double x, y, z;
};
D3 d3(const Vec3& v) { return {v.x, v.y, v.z}; }
D3 operator-(const D3& a, const D3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
D3 operator+(const D3& a, const D3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
D3 operator*(const D3& a, double s) { return {a.x * s, a.y * s, a.z * s}; }
double dot(const D3& a, const D3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
D3 cross(const D3& a, const D3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

Vec3 unit(const D3& v) {
  double l = std::sqrt(dot(v, v));
  if (!(l > 0)) return {0, 1, 0};
  return {static_cast<float>(v.x / l), static_cast<float>(v.y / l), static_cast<float>(v.z / l)};
}

// One directed edge of a triangle, for finding the triangle across each edge.
struct HalfEdge {
  uint64_t key;  // the two vertex indices, smaller first
  int slot;      // 3 * triangle + k
  bool forward;  // runs from the smaller index to the larger
};

std::vector<HalfEdge> half_edges(const std::vector<std::array<int, 3>>& tri) {
  std::vector<HalfEdge> e;
  e.reserve(3 * tri.size());
  for (size_t t = 0; t < tri.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      uint32_t a = static_cast<uint32_t>(tri[t][k]), b = static_cast<uint32_t>(tri[t][(k + 1) % 3]);
      e.push_back({(uint64_t(std::min(a, b)) << 32) | std::max(a, b), int(3 * t + k), a < b});
    }
  std::sort(e.begin(), e.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.key != y.key ? x.key < y.key : x.slot < y.slot;
  });
  return e;
}

}  // namespace

std::shared_ptr<const MeshShape> MeshShape::build(const Mesh& in, std::string* problem) {
  auto shape = std::make_shared<MeshShape>();
  MeshShape& s = *shape;
  const int nv = static_cast<int>(in.vertices.size());
  // weld vertices at equal positions, so that seams split by an exporter still close the mesh
  std::vector<int> order(nv), remap(nv);
  std::iota(order.begin(), order.end(), 0);
  auto less = [&](int a, int b) {
    const Vec3 &p = in.vertices[a], &q = in.vertices[b];
    if (p.x != q.x) return p.x < q.x;
    if (p.y != q.y) return p.y < q.y;
    if (p.z != q.z) return p.z < q.z;
    return a < b;
  };
  std::sort(order.begin(), order.end(), less);
  auto same = [&](int a, int b) {
    const Vec3 &p = in.vertices[a], &q = in.vertices[b];
    return p.x == q.x && p.y == q.y && p.z == q.z;
  };
  for (int k = 0; k < nv; ++k) {
    const int v = order[k];
    if (k > 0 && same(order[k - 1], v)) {
      remap[v] = remap[order[k - 1]];
    } else {
      remap[v] = static_cast<int>(s.mesh_.vertices.size());
      s.mesh_.vertices.push_back(in.vertices[v]);
    }
  }
  // triangles of non-zero area only
  for (const auto& t : in.triangles) {
    for (int k = 0; k < 3; ++k)
      if (t[k] < 0 || t[k] >= nv) {
        *problem = "triangle vertex " + std::to_string(t[k]) + " is out of range (" +
                   std::to_string(nv) + " vertices)";
        return nullptr;
      }
    std::array<int, 3> w = {remap[t[0]], remap[t[1]], remap[t[2]]};
    const D3 a = d3(s.mesh_.vertices[w[0]]), b = d3(s.mesh_.vertices[w[1]]),
             c = d3(s.mesh_.vertices[w[2]]);
    const D3 n = cross(b - a, c - a);
    if (dot(n, n) > 0) s.mesh_.triangles.push_back(w);
  }
  if (s.mesh_.triangles.empty()) {
    *problem = in.triangles.empty() ? "has no triangles (a collider mesh needs faces)"
                                    : "has no triangle of non-zero area";
    return nullptr;
  }
  auto& tri = s.mesh_.triangles;
  // closed: every edge in exactly two triangles, which run along it in opposite directions
  std::vector<HalfEdge> edges = half_edges(tri);
  s.closed_ = true;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    if (j - i != 2 || edges[i].forward == edges[i + 1].forward) s.closed_ = false;
    i = j;
  }
  if (s.closed_) {  // wound inward (negative volume): turn it outward
    double volume = 0;
    for (const auto& t : tri)
      volume += dot(d3(s.mesh_.vertices[t[0]]),
                    cross(d3(s.mesh_.vertices[t[1]]), d3(s.mesh_.vertices[t[2]])));
    if (volume < 0) {
      for (auto& t : tri) std::swap(t[1], t[2]);
      edges = half_edges(tri);
    }
  }
  const size_t nt = tri.size();
  std::vector<Vec3> face(nt);
  std::vector<D3> face_d(nt);
  for (size_t t = 0; t < nt; ++t) {
    const D3 a = d3(s.mesh_.vertices[tri[t][0]]), b = d3(s.mesh_.vertices[tri[t][1]]),
             c = d3(s.mesh_.vertices[tri[t][2]]);
    D3 n = cross(b - a, c - a);
    n = n * (1.0 / std::sqrt(dot(n, n)));
    face_d[t] = n;
    face[t] = unit(n);
  }
  // edge pseudonormals: the sum of the two faces' normals (one face on a boundary edge)
  std::vector<D3> edge_d(3 * nt);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) edge_d[3 * t + k] = face_d[t];
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    if (j - i == 2) {
      const int x = edges[i].slot, y = edges[i + 1].slot;
      edge_d[x] = edge_d[y] = face_d[x / 3] + face_d[y / 3];
    }
    i = j;
  }
  // vertex pseudonormals: incident face normals weighted by the angle at the vertex
  std::vector<D3> vert_d(s.mesh_.vertices.size(), D3{0, 0, 0});
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const D3 p = d3(s.mesh_.vertices[tri[t][k]]);
      const D3 u = d3(s.mesh_.vertices[tri[t][(k + 1) % 3]]) - p,
               v = d3(s.mesh_.vertices[tri[t][(k + 2) % 3]]) - p;
      const double angle = std::atan2(std::sqrt(dot(cross(u, v), cross(u, v))), dot(u, v));
      vert_d[tri[t][k]] = vert_d[tri[t][k]] + face_d[t] * angle;
    }
  s.vertex_n_.resize(vert_d.size());
  for (size_t v = 0; v < vert_d.size(); ++v) s.vertex_n_[v] = unit(vert_d[v]);

  // bounds
  s.lo_ = s.hi_ = s.mesh_.vertices[0];
  for (const Vec3& v : s.mesh_.vertices) {
    s.lo_ = {std::min(s.lo_.x, v.x), std::min(s.lo_.y, v.y), std::min(s.lo_.z, v.z)};
    s.hi_ = {std::max(s.hi_.x, v.x), std::max(s.hi_.y, v.y), std::max(s.hi_.z, v.z)};
    s.bound_radius_ = std::max(s.bound_radius_, length(v));
  }

  // the hierarchy: median split of the triangles' centroids along the longest axis
  std::vector<int> perm(nt);
  std::iota(perm.begin(), perm.end(), 0);
  std::vector<Vec3> centroid(nt);
  for (size_t t = 0; t < nt; ++t)
    centroid[t] = (s.mesh_.vertices[tri[t][0]] + s.mesh_.vertices[tri[t][1]] +
                   s.mesh_.vertices[tri[t][2]]) / 3.0f;
  s.nodes_.reserve(2 * nt);
  s.nodes_.push_back({});
  struct Task {
    int node, first, count;
  };
  std::vector<Task> todo{{0, 0, static_cast<int>(nt)}};
  while (!todo.empty()) {
    const Task task = todo.back();
    todo.pop_back();
    Node nd;
    for (int k = 0; k < 3; ++k) {
      nd.lo[k] = std::numeric_limits<float>::max();
      nd.hi[k] = -std::numeric_limits<float>::max();
    }
    Vec3 clo = centroid[perm[task.first]], chi = clo;
    for (int i = task.first; i < task.first + task.count; ++i) {
      for (int corner = 0; corner < 3; ++corner) {
        const Vec3& v = s.mesh_.vertices[tri[perm[i]][corner]];
        for (int k = 0; k < 3; ++k) {
          nd.lo[k] = std::min(nd.lo[k], v[k]);
          nd.hi[k] = std::max(nd.hi[k], v[k]);
        }
      }
      const Vec3& c = centroid[perm[i]];
      clo = {std::min(clo.x, c.x), std::min(clo.y, c.y), std::min(clo.z, c.z)};
      chi = {std::max(chi.x, c.x), std::max(chi.y, c.y), std::max(chi.z, c.z)};
    }
    const Vec3 ext = chi - clo;
    const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    if (task.count <= 4 || !(ext[axis] > 0)) {
      nd.first = task.first;
      nd.count = task.count;
      s.nodes_[task.node] = nd;
      continue;
    }
    const int mid = task.first + task.count / 2;
    std::nth_element(perm.begin() + task.first, perm.begin() + mid,
                     perm.begin() + task.first + task.count,
                     [&](int a, int b) { return centroid[a][axis] < centroid[b][axis]; });
    nd.first = static_cast<int>(s.nodes_.size());
    nd.count = 0;
    s.nodes_[task.node] = nd;
    s.nodes_.push_back({});
    s.nodes_.push_back({});
    todo.push_back({nd.first, task.first, mid - task.first});
    todo.push_back({nd.first + 1, mid, task.first + task.count - mid});
  }
  s.tri_.resize(nt);
  s.face_n_.resize(nt);
  s.edge_n_.resize(3 * nt);
  for (size_t i = 0; i < nt; ++i) {
    const int t = perm[i];
    s.tri_[i] = tri[t];
    s.face_n_[i] = face[t];
    for (int k = 0; k < 3; ++k) s.edge_n_[3 * i + k] = unit(edge_d[3 * t + k]);
  }
  s.point_view();
  return shape;
}

static_assert(sizeof(Vec3) == 3 * sizeof(float) && sizeof(std::array<int, 3>) == 3 * sizeof(int),
              "the arrays as engine/mesh_query.h reads them");

void MeshShape::point_view() {
  gr_mesh& m = view_;
  m.nodes = nodes_.data();
  m.tri = tri_.empty() ? nullptr : tri_[0].data();
  m.vertices = mesh_.vertices.empty() ? nullptr : &mesh_.vertices[0].x;
  m.face_n = face_n_.empty() ? nullptr : &face_n_[0].x;
  m.edge_n = edge_n_.empty() ? nullptr : &edge_n_[0].x;
  m.vertex_n = vertex_n_.empty() ? nullptr : &vertex_n_[0].x;
  for (int k = 0; k < 3; ++k) m.lo[k] = lo_[k], m.hi[k] = hi_[k];
  m.closed = closed_ ? 1 : 0;
}

float MeshShape::crossing(const Vec3& a, const Vec3& b, Vec3* normal) const {
  const gr_mesh& m = view_;
  const float af[3] = {a.x, a.y, a.z}, bf[3] = {b.x, b.y, b.z};
  float n[3];
  const float t = gr_mesh_query_crossing(&m, af, bf, n);
  if (normal && t <= 1.0f) *normal = {n[0], n[1], n[2]};
  return t;
}

float MeshShape::distance(const Vec3& p, Vec3* normal, float within) const {
  const gr_mesh& m = view_;
  const float at[3] = {p.x, p.y, p.z};
  float n[3];
  const float d = gr_mesh_query_distance(&m, at, normal ? n : nullptr, within);
  if (normal) *normal = {n[0], n[1], n[2]};
  return d;
}

}  // namespace grains
