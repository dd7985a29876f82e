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

// Where on a triangle the nearest point lies: its face, one of its vertices, one of its edges
// (edge k joins vertex k and vertex (k + 1) % 3).
enum Feature { kFace, kVertex0, kVertex1, kVertex2, kEdge0, kEdge1, kEdge2 };

// The point of triangle (a, b, c) nearest to p, and its feature (Ericson, Real-Time Collision
// Detection §5.1.5: the Voronoi regions of the vertices, then the edges, then the face).
D3 closest_on_triangle(const D3& p, const D3& a, const D3& b, const D3& c, Feature* f) {
  const D3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return *f = kVertex0, a;
  const D3 bp = p - b;
  const double d3v = dot(ab, bp), d4 = dot(ac, bp);
  if (d3v >= 0 && d4 <= d3v) return *f = kVertex1, b;
  const double vc = d1 * d4 - d3v * d2;
  if (vc <= 0 && d1 >= 0 && d3v <= 0) return *f = kEdge0, a + ab * (d1 / (d1 - d3v));
  const D3 cp = p - c;
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return *f = kVertex2, c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return *f = kEdge2, a + ac * (d2 / (d2 - d6));
  const double va = d3v * d6 - d5 * d4;
  if (va <= 0 && d4 - d3v >= 0 && d5 - d6 >= 0)
    return *f = kEdge1, b + (c - b) * ((d4 - d3v) / ((d4 - d3v) + (d5 - d6)));
  const double inv = 1.0 / (va + vb + vc);
  return *f = kFace, a + ab * (vb * inv) + ac * (vc * inv);
}

// Squared distance from p to the box [lo, hi] (0 inside).
double box_distance2(const float* lo, const float* hi, const D3& p) {
  const double q[3] = {p.x, p.y, p.z};
  double s = 0;
  for (int k = 0; k < 3; ++k) {
    double e = q[k] < lo[k] ? lo[k] - q[k] : (q[k] > hi[k] ? q[k] - hi[k] : 0.0);
    s += e * e;
  }
  return s;
}

// The parameter range [t0, t1] within [0, 1] over which p + t d lies in the box [lo, hi]
// (slab test); false when it never does. inv_d: 1 / d per axis (infinite for a zero component).
bool segment_box(const float* lo, const float* hi, const D3& p, const D3& inv_d, double* t_in) {
  const double q[3] = {p.x, p.y, p.z}, id[3] = {inv_d.x, inv_d.y, inv_d.z};
  double t0 = 0, t1 = 1;
  for (int k = 0; k < 3; ++k) {
    if (std::isinf(id[k])) {
      if (q[k] < lo[k] || q[k] > hi[k]) return false;
      continue;
    }
    double ta = (lo[k] - q[k]) * id[k], tb = (hi[k] - q[k]) * id[k];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  *t_in = t0;
  return true;
}

// Where p + t d meets triangle (a, b, c), t in [0, 1] (Moeller & Trumbore 1997); a negative
// value when it does not. Points on an edge count for both triangles that share it.
double segment_triangle(const D3& p, const D3& d, const D3& a, const D3& b, const D3& c) {
  const D3 e1 = b - a, e2 = c - a, h = cross(d, e2);
  const double det = dot(e1, h);
  if (std::fabs(det) < 1e-300) return -1;  // parallel
  const double inv = 1.0 / det;
  const D3 s = p - a;
  const double u = dot(s, h) * inv;
  if (u < 0 || u > 1) return -1;
  const D3 q = cross(s, e1);
  const double v = dot(d, q) * inv;
  if (v < 0 || u + v > 1) return -1;
  const double t = dot(e2, q) * inv;
  return t >= 0 && t <= 1 ? t : -1;
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
  return shape;
}

float MeshShape::crossing(const Vec3& af, const Vec3& bf, Vec3* normal) const {
  const D3 p = d3(af), d = d3(bf) - p;
  const double inf = std::numeric_limits<double>::infinity();
  const D3 inv_d{d.x != 0 ? 1 / d.x : inf, d.y != 0 ? 1 / d.y : inf, d.z != 0 ? 1 / d.z : inf};
  double best = inf;
  int best_t = -1;
  int stack[64];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& nd = nodes_[stack[--top]];
    double t_in;
    if (!segment_box(nd.lo, nd.hi, p, inv_d, &t_in) || t_in > best) continue;
    if (nd.count == 0) {
      stack[top++] = nd.first;
      stack[top++] = nd.first + 1;
      continue;
    }
    for (int i = nd.first; i < nd.first + nd.count; ++i) {
      const auto& t = tri_[i];
      const double hit = segment_triangle(p, d, d3(mesh_.vertices[t[0]]),
                                          d3(mesh_.vertices[t[1]]), d3(mesh_.vertices[t[2]]));
      if (hit > 0 && hit < best) best = hit, best_t = i;  // a start on the surface is on no side
    }
  }
  if (best_t < 0) return 2.0f;
  if (normal) *normal = face_n_[best_t];
  return static_cast<float>(best);
}

float MeshShape::distance(const Vec3& pf, Vec3* normal, float within) const {
  const D3 p = d3(pf);
  const double cap = within > 0 ? double(within) * double(within) : 0.0;
  double best = cap;
  D3 best_c{0, 0, 0};
  int best_t = -1;
  Feature best_f = kFace;
  // each visit pops one node and pushes at most two, so the stack holds at most depth + 1
  // nodes; median splits of fewer than 2^31 triangles are under 32 deep
  int stack[64];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& nd = nodes_[stack[--top]];
    if (box_distance2(nd.lo, nd.hi, p) >= best) continue;
    if (nd.count > 0) {
      for (int i = nd.first; i < nd.first + nd.count; ++i) {
        const auto& t = tri_[i];
        Feature f;
        const D3 c = closest_on_triangle(p, d3(mesh_.vertices[t[0]]), d3(mesh_.vertices[t[1]]),
                                         d3(mesh_.vertices[t[2]]), &f);
        const D3 d = p - c;
        const double d2 = dot(d, d);
        if (d2 < best) {
          best = d2;
          best_c = c;
          best_t = i;
          best_f = f;
        }
      }
      continue;
    }
    // nearer child on top of the stack
    const int a = nd.first, b = nd.first + 1;
    const double da = box_distance2(nodes_[a].lo, nodes_[a].hi, p);
    const double db = box_distance2(nodes_[b].lo, nodes_[b].hi, p);
    const bool a_first = da <= db;
    const int near = a_first ? a : b, far = a_first ? b : a;
    const double dnear = a_first ? da : db, dfar = a_first ? db : da;
    if (dfar < best) stack[top++] = far;
    if (dnear < best) stack[top++] = near;
  }
  if (best_t < 0) {  // nothing nearer than `within`
    const double box = std::sqrt(box_distance2(&lo_.x, &hi_.x, p));
    // a closed mesh's far point may be inside it: only the whole walk tells the sign
    if (closed_ && box == 0 && std::isfinite(cap))
      return distance(pf, normal, std::numeric_limits<float>::infinity());
    if (normal) *normal = {0, 1, 0};
    return static_cast<float>(std::max(double(within), box));
  }
  Vec3 pseudo;
  switch (best_f) {
    case kFace: pseudo = face_n_[best_t]; break;
    case kVertex0: case kVertex1: case kVertex2:
      pseudo = vertex_n_[tri_[best_t][best_f - kVertex0]];
      break;
    default: pseudo = edge_n_[3 * best_t + (best_f - kEdge0)]; break;
  }
  const D3 away = p - best_c;
  const double dist = std::sqrt(best);
  const double side = dot(away, d3(pseudo));
  // a shell has no inside: the distance is unsigned, the normal points toward p
  const double sign = closed_ && side < 0 ? -1.0 : 1.0;
  if (normal) {
    if (dist > 1e-12) {
      *normal = unit(away * sign);
    } else {
      *normal = pseudo;
    }
  }
  return static_cast<float>(sign * dist);
}

}  // namespace grains
