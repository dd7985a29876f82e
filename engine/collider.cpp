#include "engine/collider.h"

#include <algorithm>
#include <cmath>

#include "engine/mesh_shape.h"

namespace grains {

const char* shape_name(ShapeKind k) {
  switch (k) {
    case ShapeKind::Plane: return "plane";
    case ShapeKind::Box: return "box";
    case ShapeKind::Sphere: return "sphere";
    case ShapeKind::Torus: return "torus";
    case ShapeKind::Capsule: return "capsule";
    case ShapeKind::Mesh: return "mesh";
  }
  return "?";
}

bool parse_shape(const std::string& s, ShapeKind& out) {
  for (ShapeKind k : {ShapeKind::Plane, ShapeKind::Box, ShapeKind::Sphere, ShapeKind::Torus,
                      ShapeKind::Capsule, ShapeKind::Mesh})
    if (s == shape_name(k)) {
      out = k;
      return true;
    }
  return false;
}

Pose Pose::from_trs(const Vec3& translate, const Vec3& rotate_deg, float scale) {
  const double k = M_PI / 180.0;
  double cx = std::cos(rotate_deg.x * k), sx = std::sin(rotate_deg.x * k);
  double cy = std::cos(rotate_deg.y * k), sy = std::sin(rotate_deg.y * k);
  double cz = std::cos(rotate_deg.z * k), sz = std::sin(rotate_deg.z * k);
  // R = Rz * Ry * Rx: rotate about x first, then y, then z (Houdini's default XYZ order)
  double m[9] = {cy * cz, sx * sy * cz - cx * sz, cx * sy * cz + sx * sz,
                 cy * sz, sx * sy * sz + cx * cz, cx * sy * sz - sx * cz,
                 -sy,     sx * cy,                cx * cy};
  Pose p;
  for (int i = 0; i < 9; ++i) p.R[i] = static_cast<float>(m[i]);
  p.t = translate;
  p.s = scale;
  return p;
}

Vec3 Pose::rotate(const Vec3& d) const {
  return {R[0] * d.x + R[1] * d.y + R[2] * d.z, R[3] * d.x + R[4] * d.y + R[5] * d.z,
          R[6] * d.x + R[7] * d.y + R[8] * d.z};
}
Vec3 Pose::unrotate(const Vec3& d) const {
  return {R[0] * d.x + R[3] * d.y + R[6] * d.z, R[1] * d.x + R[4] * d.y + R[7] * d.z,
          R[2] * d.x + R[5] * d.y + R[8] * d.z};
}
Vec3 Pose::apply(const Vec3& local) const { return t + rotate(local) * s; }
Vec3 Pose::inverse(const Vec3& world) const { return unrotate(world - t) / s; }

float shape_distance(const Shape& sh, const Vec3& p, Vec3* normal, float within) {
  switch (sh.kind) {
    case ShapeKind::Plane:
      if (normal) *normal = {0, 1, 0};
      return p.y;
    case ShapeKind::Sphere: {
      float l = length(p);
      if (normal) *normal = l > 0 ? p / l : Vec3{0, 1, 0};
      return l - sh.radius;
    }
    case ShapeKind::Box: {
      Vec3 h = sh.size * 0.5f;
      Vec3 q{std::fabs(p.x) - h.x, std::fabs(p.y) - h.y, std::fabs(p.z) - h.z};
      Vec3 qo{std::max(q.x, 0.0f), std::max(q.y, 0.0f), std::max(q.z, 0.0f)};
      float outside = length(qo);
      float inside = std::min(std::max(q.x, std::max(q.y, q.z)), 0.0f);
      if (normal) {
        Vec3 n;
        if (outside > 0) {
          n = qo / outside;
        } else {  // inside: push out through the nearest face
          int a = (q.x >= q.y && q.x >= q.z) ? 0 : (q.y >= q.z ? 1 : 2);
          n[a] = 1;
        }
        *normal = Vec3{p.x < 0 ? -n.x : n.x, p.y < 0 ? -n.y : n.y, p.z < 0 ? -n.z : n.z};
      }
      return outside + inside;
    }
    case ShapeKind::Torus: {
      float lxz = std::sqrt(p.x * p.x + p.z * p.z);
      Vec3 ring = lxz > 0 ? Vec3{p.x / lxz * sh.radius, 0, p.z / lxz * sh.radius}
                          : Vec3{sh.radius, 0, 0};
      Vec3 d = p - ring;
      float l = length(d);
      if (normal) *normal = l > 0 ? d / l : Vec3{0, 1, 0};
      return l - sh.tube;
    }
    case ShapeKind::Capsule: {
      float hy = sh.height * 0.5f;
      Vec3 c{0, std::clamp(p.y, -hy, hy), 0};
      Vec3 d = p - c;
      float l = length(d);
      if (normal) *normal = l > 0 ? d / l : Vec3{1, 0, 0};
      return l - sh.radius;
    }
    case ShapeKind::Mesh:
      if (!sh.mesh) break;
      return sh.mesh->distance(p, normal, within);
  }
  if (normal) *normal = {0, 1, 0};
  return 1e30f;
}

float ColliderState::distance(const Vec3& p, Vec3* normal, float within) const {
  Vec3 nl;
  float d = shape_distance(shape, pose.inverse(p), normal ? &nl : nullptr, within / pose.s) * pose.s;
  if (normal) *normal = pose.rotate(nl);
  return d;
}

Vec3 ColliderState::velocity_at(const Vec3& p) const {
  if (dt <= 0) return {0, 0, 0};
  return (p - carried_back(p)) / dt;
}

bool ColliderState::shell() const {
  return shape.kind == ShapeKind::Mesh && shape.mesh && !shape.mesh->closed();
}

float ColliderState::shell_crossing(const Vec3& a, const Vec3& b, Vec3* at, Vec3* side) const {
  if (!shell()) return 2.0f;
  const Vec3 la = prev_pose.inverse(a), lb = pose.inverse(b);
  Vec3 n;
  const float t = shape.mesh->crossing(la, lb, &n);
  if (!(t <= 1.0f)) return 2.0f;
  *at = pose.apply(la + (lb - la) * t);
  // the point came from the side its path leaves behind
  *side = pose.rotate(dot(lb - la, n) > 0 ? -n : n);
  return t;
}

bool ColliderState::still() const {
  for (int k = 0; k < 9; ++k)
    if (pose.R[k] != prev_pose.R[k]) return false;
  return pose.t.x == prev_pose.t.x && pose.t.y == prev_pose.t.y && pose.t.z == prev_pose.t.z &&
         pose.s == prev_pose.s;
}

float ColliderState::sweep(const Vec3& a, const Vec3& b, float radius) const {
  // relative motion in the collider's local frame: start against the start pose, end against
  // the end pose; then sphere-trace the segment against the static local shape
  Vec3 la = prev_pose.inverse(a), lb = pose.inverse(b);
  float r = radius / pose.s;
  Vec3 d = lb - la;
  float len = length(d);
  // a step needs the distance only up to what is left of the segment (past it the trace ends)
  float dist0 = shape_distance(shape, la, nullptr, 2 * r + len);
  if (dist0 <= r) return 0.0f;
  if (len <= 0) return 2.0f;
  Vec3 dir = d / len;
  float s = 0;
  for (int it = 0; it < 256; ++it) {
    float dist = shape_distance(shape, la + dir * s, nullptr, 2 * r + (len - s)) - r;
    if (dist <= 1e-6f * (1.0f + len)) return s / len;
    s += dist;
    if (s > len) break;
  }
  // the end point may still be inside if tracing stopped short of it
  return shape_distance(shape, lb, nullptr, 2 * r) <= r ? 1.0f : 2.0f;
}

}  // namespace grains
