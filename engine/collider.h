// Collider shapes and their poses. Each shape is an exact signed distance in its local frame;
// a pose (rotation, translation, uniform scale) places it in the world and, with the pose a
// substep earlier, gives the surface velocity that collider friction matches.
#pragma once
#include <limits>
#include <memory>
#include <string>

#include "engine/collider_shape.h"
#include "engine/vec3.h"

namespace grains {

enum class ShapeKind { Plane, Box, Sphere, Torus, Capsule, Mesh };
const char* shape_name(ShapeKind k);
bool parse_shape(const std::string& s, ShapeKind& out);

// Local shapes: plane y = 0 with solid below (normal +y); box centred, full extents `size`;
// sphere of `radius`; torus in the xz plane, `radius` (ring) and `tube`; capsule along y with
// `height` between the hemisphere centres and `radius`; mesh: the triangles of `mesh`
// (engine/mesh_shape.h: signed when closed, a two-sided shell otherwise).
class MeshShape;
struct Shape {
  ShapeKind kind = ShapeKind::Plane;
  Vec3 size{1, 1, 1};
  float radius = 0.5f;
  float tube = 0.1f;
  float height = 1.0f;
  std::shared_ptr<const MeshShape> mesh;  // shape mesh only; shared, never changed once built
};

// Rigid placement with uniform scale: world = t + s * R * local.
struct Pose {
  float R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // row-major rotation
  Vec3 t{0, 0, 0};
  float s = 1.0f;
  static Pose from_trs(const Vec3& translate, const Vec3& rotate_deg, float scale);  // XYZ order
  Vec3 apply(const Vec3& local) const;
  Vec3 inverse(const Vec3& world) const;
  Vec3 rotate(const Vec3& local_dir) const;
  Vec3 unrotate(const Vec3& world_dir) const;
};

// Signed distance in the shape's local frame (negative inside) and the outward normal. Exact
// below `within`; a point at least `within` outside may get any value from `within` up to its
// distance, and any normal (a mesh then skips the triangles beyond; analytic shapes are exact).
float shape_distance(const Shape& shape, const Vec3& p, Vec3* normal,
                     float within = std::numeric_limits<float>::infinity());

// A collider at one substep: its shape, pose now and pose at the previous substep.
struct ColliderState {
  std::string name;
  Shape shape;
  Pose pose;       // at the end of the substep
  Pose prev_pose;  // at the start of the substep
  float dt = 0;    // substep length (s), for velocities
  float bounce = 0.0f;    // restitution for the POP solver's response
  float friction = 0.5f;  // Coulomb friction for the POP solver's response

  // World signed distance and outward normal at p (end pose); `within` as shape_distance's,
  // in world units.
  float distance(const Vec3& p, Vec3* normal,
                 float within = std::numeric_limits<float>::infinity()) const;
  // Velocity of the collider's material at world point p (m/s).
  Vec3 velocity_at(const Vec3& p) const;
  // Where p, carried rigidly by the collider, was at the start of the substep.
  Vec3 carried_back(const Vec3& p) const { return prev_pose.apply(pose.inverse(p)); }
  // Continuous test: a sphere of `radius` moving from `a` (start of substep, world) to `b`
  // (end of substep, world), relative to the collider's own motion. Returns the fraction in
  // [0,1] of the first time its distance reaches `radius`, or a value > 1 when it never does.
  float sweep(const Vec3& a, const Vec3& b, float radius) const;
  // True for an open mesh: a two-sided shell with no inside, whose distance cannot tell which
  // side a grain is on.
  bool shell() const;
  // For a shell: where a point moving from `a` (start of substep, world) to `b` (end, world)
  // passed through it, relative to its motion. Returns the fraction along the path (> 1 when it
  // did not), *at the crossing point carried to the end pose and *side the shell's normal
  // there turned toward the side the point came from.
  float shell_crossing(const Vec3& a, const Vec3& b, Vec3* at, Vec3* side) const;
  // True when the collider did not move over the substep (same pose, bit for bit).
  bool still() const;
};

// The shared definitions' (engine/collider_shape.h) forms of a pose, a shape and a collider
// over a substep (a mesh keeps only its kind there).
gr_pose to_gr(const Pose& q);
gr_shape to_gr(const Shape& sh);
gr_collider to_gr(const ColliderState& c);

}  // namespace grains
