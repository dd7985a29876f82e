// collider: a plane, box, sphere, torus, capsule or triangle mesh with a transform that
// expressions or keyframes may animate. Solvers list colliders by name; the evaluator poses them every substep, and the
// pose a substep earlier gives the surface velocity.
#include "engine/geometry_io.h"
#include "engine/mesh_shape.h"
#include "engine/node.h"
#include "engine/param_rows.h"
#include "nodes/common.h"
#include "nodes/register.h"

namespace grains {
namespace {

// the node's parameters (engine/param_rows.h); shape's menu is in ShapeKind's order
#define COLLIDER_PARAMS(ROW)                                                                    \
  ROW(MENU, shape, 0, .menu_of({"plane", "box", "sphere", "torus", "capsule", "mesh"}),         \
      "plane (y = 0, solid below, before the transform), box, sphere, torus (in xz), capsule "   \
      "(along y), mesh (the triangles of `file`: a solid when closed, a two-sided shell when open)") \
  ROW(STRING, file, "", ,                                                                       \
      "mesh: OBJ or PLY triangle mesh in the collider's local frame, relative to the graph")      \
  ROW(VECTOR, size, (1, 1, 1), .unit("m"), "full extents of the box")                           \
  ROW(FLOAT, radius, 0.5, .positive().unit("m"), "sphere and capsule radius; torus ring radius") \
  ROW(FLOAT, tube, 0.1, .positive().unit("m"), "torus tube radius")                             \
  ROW(FLOAT, height, 1, .at_least(0).unit("m"), "capsule length between hemisphere centres")   \
  ROW(VECTOR, normal, (0, 1, 0), ,                                                              \
      "plane normal (before rotate); the plane passes through translate")                       \
  ROW(VECTOR, translate, (0, 0, 0), .unit("m"), "translation")                                  \
  ROW(VECTOR, rotate, (0, 0, 0), .unit("deg"), "rotation about x, then y, then z")              \
  ROW(FLOAT, scale, 1, .positive(), "uniform scale")                                            \
  ROW(FLOAT, bounce, 0.5, .range(0, 1), "restitution of the solver's response (non-grains points)") \
  ROW(FLOAT, friction, 0.5, .at_least(0),                                                       \
      "Coulomb friction of the solver's response (non-grains points)")
GR_NODE_PARAMS(ColliderParams, COLLIDER_PARAMS)

}  // namespace

void register_collider_node() {
  NodeTypeInfo t;
  t.type = "collider";
  t.doc = "A collision shape with an animatable transform, referenced by solvers' `colliders`.";
  t.role = NodeRole::Collider;
  t.params = ColliderParams::decls();
  t.collider = [](const ParamSet& params, const std::string& base_dir, ColliderState& c) {
    const ColliderParams p = ColliderParams::read(params);
    c.shape.kind = static_cast<ShapeKind>(p.shape.index);
    c.shape.mesh = c.shape.kind == ShapeKind::Mesh ? cached_mesh_shape(resolve_path(base_dir, p.file))
                                                   : nullptr;
    c.shape.size = p.size;
    c.shape.radius = static_cast<float>(p.radius);
    c.shape.tube = static_cast<float>(p.tube);
    c.shape.height = static_cast<float>(p.height);
    c.bounce = static_cast<float>(p.bounce);
    c.friction = static_cast<float>(p.friction);
    Pose pose = Pose::from_trs(p.translate, p.rotate, static_cast<float>(p.scale));
    if (c.shape.kind == ShapeKind::Plane) {
      // turn local +y onto the normal, then apply the transform's rotation
      Vec3 n = normalized(p.normal);
      Vec3 y{0, 1, 0};
      Vec3 axis = cross(y, n);
      float s = length(axis), co = dot(y, n);
      float R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
      if (s > 1e-7f) {
        axis = axis / s;
        float C = 1 - co;
        float x = axis.x, yy = axis.y, z = axis.z;
        float M[9] = {co + x * x * C,      x * yy * C - z * s,  x * z * C + yy * s,
                      yy * x * C + z * s,  co + yy * yy * C,    yy * z * C - x * s,
                      z * x * C - yy * s,  z * yy * C + x * s,  co + z * z * C};
        for (int i = 0; i < 9; ++i) R[i] = M[i];
      } else if (co < 0) {
        R[4] = -1;
        R[8] = -1;
      }
      float out[9];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          out[3 * i + j] = pose.R[3 * i] * R[j] + pose.R[3 * i + 1] * R[3 + j] + pose.R[3 * i + 2] * R[6 + j];
      for (int i = 0; i < 9; ++i) pose.R[i] = out[i];
    }
    c.pose = pose;
  };
  t.check = [](const ParamSet& p, const std::string& base) -> std::pair<std::string, std::string> {
    const ColliderParams q = ColliderParams::read(p);
    if (q.shape == static_cast<int>(ShapeKind::Mesh)) {
      if (q.file.empty()) return {"shape \"mesh\" needs a `file`", "file"};
      try {
        (void)cached_mesh_shape(resolve_path(base, q.file));
      } catch (const GeometryError& e) {
        return {e.what(), "file"};
      }
    }
    if (q.shape == static_cast<int>(ShapeKind::Plane) && length(q.normal) == 0 &&
        !p.is_animated("normal"))
      return {"the plane normal must not be zero", "normal"};
    return {"", ""};
  };
  register_node_type(std::move(t));
}

}  // namespace grains
