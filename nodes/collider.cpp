// collider: a plane, box, sphere, torus or capsule with a transform that expressions or keyframes
// may animate. Solvers list colliders by name; the evaluator poses them every substep, and the
// pose a substep earlier gives the surface velocity.
#include "engine/node.h"
#include "nodes/register.h"

namespace grains {

void register_collider_node() {
  NodeTypeInfo t;
  t.type = "collider";
  t.doc = "A collision shape with an animatable transform, referenced by solvers' `colliders`.";
  t.role = NodeRole::Collider;
  t.params = {
      ParamDecl::Menu("shape", {"plane", "box", "sphere", "torus", "capsule"}, "plane",
                      "plane (y = 0, solid below, before the transform), box, sphere, torus (in xz), capsule (along y)"),
      ParamDecl::Vector("size", {1, 1, 1}, "full extents of the box").unit("m"),
      ParamDecl::Float("radius", 0.5, "sphere and capsule radius; torus ring radius").positive().unit("m"),
      ParamDecl::Float("tube", 0.1, "torus tube radius").positive().unit("m"),
      ParamDecl::Float("height", 1, "capsule length between hemisphere centres").at_least(0).unit("m"),
      ParamDecl::Vector("normal", {0, 1, 0}, "plane normal (before rotate); the plane passes through translate"),
      ParamDecl::Vector("translate", {0, 0, 0}, "translation").unit("m"),
      ParamDecl::Vector("rotate", {0, 0, 0}, "rotation about x, then y, then z").unit("deg"),
      ParamDecl::Float("scale", 1, "uniform scale").positive(),
      ParamDecl::Float("bounce", 0.5, "restitution of the solver's response (non-grains points)").range(0, 1),
      ParamDecl::Float("friction", 0.5, "Coulomb friction of the solver's response (non-grains points)").at_least(0),
  };
  t.collider = [](const ParamSet& p, ColliderState& c) {
    c.shape.kind = static_cast<ShapeKind>(p.choice("shape"));  // the menu is in ShapeKind's order
    c.shape.size = p.v3("size");
    c.shape.radius = static_cast<float>(p.f("radius"));
    c.shape.tube = static_cast<float>(p.f("tube"));
    c.shape.height = static_cast<float>(p.f("height"));
    c.bounce = static_cast<float>(p.f("bounce"));
    c.friction = static_cast<float>(p.f("friction"));
    Pose pose = Pose::from_trs(p.v3("translate"), p.v3("rotate"), static_cast<float>(p.f("scale")));
    if (c.shape.kind == ShapeKind::Plane) {
      // turn local +y onto the normal, then apply the transform's rotation
      Vec3 n = normalized(p.v3("normal"));
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
  t.check = [](const ParamSet& p, const std::string&) -> std::pair<std::string, std::string> {
    if (p.s("shape") == "plane" && length(p.v3("normal")) == 0 && !p.is_animated("normal"))
      return {"the plane normal must not be zero", "normal"};
    return {"", ""};
  };
  register_node_type(std::move(t));
}

}  // namespace grains
