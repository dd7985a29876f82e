#include "engine/collider.h"

#include <algorithm>
#include <cmath>

#include "engine/collider_shape.h"
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

// The analytic shapes and the poses are engine/collider_shape.h's, which an OpenCL device
// compiles too: the two find the same floats.
static_assert(int(ShapeKind::Plane) == GR_SHAPE_PLANE && int(ShapeKind::Box) == GR_SHAPE_BOX &&
                  int(ShapeKind::Sphere) == GR_SHAPE_SPHERE &&
                  int(ShapeKind::Torus) == GR_SHAPE_TORUS &&
                  int(ShapeKind::Capsule) == GR_SHAPE_CAPSULE &&
                  int(ShapeKind::Mesh) == GR_SHAPE_MESH,
              "ShapeKind in collider_shape.h's order");
static_assert(sizeof(gr_collider) == 136, "the same layout on the host and a device");

gr_pose to_gr(const Pose& q) {
  gr_pose g;
  for (int k = 0; k < 9; ++k) g.R[k] = q.R[k];
  g.t[0] = q.t.x, g.t[1] = q.t.y, g.t[2] = q.t.z;
  g.s = q.s;
  return g;
}

gr_shape to_gr(const Shape& sh) {
  gr_shape g;
  g.kind = static_cast<int>(sh.kind);
  g.size[0] = sh.size.x, g.size[1] = sh.size.y, g.size[2] = sh.size.z;
  g.radius = sh.radius;
  g.tube = sh.tube;
  g.height = sh.height;
  return g;
}

gr_collider to_gr(const ColliderState& c) {
  gr_collider g;
  g.shape = to_gr(c.shape);
  g.pose = to_gr(c.pose);
  g.prev = to_gr(c.prev_pose);
  g.dt = c.dt;
  return g;
}

namespace {
Vec3 vec(const float* a) {
  return {a[0], a[1], a[2]};
}

// v through one of the shared pose functions (engine/collider_shape.h)
Vec3 through(const Pose& q, const Vec3& v, void (*f)(const gr_pose*, const float*, float*)) {
  const gr_pose g = to_gr(q);
  const float in[3] = {v.x, v.y, v.z};
  float out[3];
  f(&g, in, out);
  return vec(out);
}
}  // namespace

Vec3 Pose::rotate(const Vec3& d) const {
  return through(*this, d, gr_pose_rotate);
}
Vec3 Pose::unrotate(const Vec3& d) const {
  return through(*this, d, gr_pose_unrotate);
}
Vec3 Pose::apply(const Vec3& local) const {
  return through(*this, local, gr_pose_apply);
}
Vec3 Pose::inverse(const Vec3& world) const {
  return through(*this, world, gr_pose_inverse);
}

float shape_distance(const Shape& sh, const Vec3& p, Vec3* normal, float within) {
  if (sh.kind == ShapeKind::Mesh && sh.mesh) return sh.mesh->distance(p, normal, within);
  const gr_shape g = to_gr(sh);
  const float at[3] = {p.x, p.y, p.z};
  float n[3];
  const float d = gr_shape_distance(&g, at, normal ? n : nullptr);
  if (normal) *normal = vec(n);
  return d;
}

float ColliderState::distance(const Vec3& p, Vec3* normal, float within) const {
  if (shape.kind == ShapeKind::Mesh) {
    Vec3 nl;
    float d =
        shape_distance(shape, pose.inverse(p), normal ? &nl : nullptr, within / pose.s) * pose.s;
    if (normal) *normal = pose.rotate(nl);
    return d;
  }
  const gr_shape sh = to_gr(shape);
  const gr_pose q = to_gr(pose);
  const float at[3] = {p.x, p.y, p.z};
  float n[3];
  const float d = gr_placed_distance(&sh, &q, at, normal ? n : nullptr);
  if (normal) *normal = vec(n);
  return d;
}

Vec3 ColliderState::velocity_at(const Vec3& p) const {
  const gr_collider g = to_gr(*this);
  const float at[3] = {p.x, p.y, p.z};
  float v[3];
  gr_collider_velocity(&g, at, v);
  return vec(v);
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
