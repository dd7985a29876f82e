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
  const gr_shape g = to_gr(sh);
  const float at[3] = {p.x, p.y, p.z};
  float n[3];
  const float d = gr_local_distance(&g, at, normal ? n : nullptr, within, sh.mesh.get());
  if (normal) *normal = vec(n);
  return d;
}

float ColliderState::distance(const Vec3& p, Vec3* normal, float within) const {
  const gr_collider g = to_gr(*this);
  const float at[3] = {p.x, p.y, p.z};
  float n[3];
  const float d =
      gr_collider_distance_within(&g, at, normal ? n : nullptr, within, shape.mesh.get());
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
  const gr_collider g = to_gr(*this);
  const float from[3] = {a.x, a.y, a.z}, to[3] = {b.x, b.y, b.z};
  float x[3], n[3];
  const float t = gr_collider_shell_crossing(&g, from, to, x, n, shape.mesh.get());
  if (t <= 1.0f) *at = vec(x), *side = vec(n);
  return t;
}

bool ColliderState::still() const {
  const gr_collider g = to_gr(*this);
  return gr_collider_still(&g) != 0;
}

float ColliderState::sweep(const Vec3& a, const Vec3& b, float radius) const {
  const gr_collider g = to_gr(*this);
  const float from[3] = {a.x, a.y, a.z}, to[3] = {b.x, b.y, b.z};
  return gr_collider_sweep(&g, from, to, radius, shape.mesh.get());
}

}  // namespace grains

// the shared functions' mesh queries (engine/collider_shape.h)
float gr_mesh_distance(const void* mesh, const float* p, float* n, float within) {
  grains::Vec3 nl;
  const float d = static_cast<const grains::MeshShape*>(mesh)->distance({p[0], p[1], p[2]},
                                                                        n ? &nl : nullptr, within);
  if (n) n[0] = nl.x, n[1] = nl.y, n[2] = nl.z;
  return d;
}

float gr_mesh_crossing(const void* mesh, const float* a, const float* b, float* n) {
  grains::Vec3 nl;
  const float t = static_cast<const grains::MeshShape*>(mesh)->crossing({a[0], a[1], a[2]},
                                                                        {b[0], b[1], b[2]}, &nl);
  n[0] = nl.x, n[1] = nl.y, n[2] = nl.z;
  return t;
}

int gr_mesh_shell(const void* mesh) {
  return static_cast<const grains::MeshShape*>(mesh)->closed() ? 0 : 1;
}
