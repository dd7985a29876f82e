// target: sets the pin target `targetP` that the grains node pulls its grains toward (help page
// "Targets (Pins)"; the KeyframedGrains and TargetSand examples).
//
//   mode "rest":    targetP = X(rest), each point's `rest` position (written by sources) through
//                   the transform X. Keyframe or animate the transform and a solid of grains
//                   follows it like a puppet (KeyframedGrains).
//   mode "surface": targetP = the point of the mesh `file` (PLY or OBJ triangles, relative to the
//                   graph), transformed by X, closest to the grain's current position: grains
//                   are drawn onto the model's surface (TargetSand).
// X(x) = R (scale * (x - pivot)) + pivot + translate, R the XYZ rotation (degrees) colliders use.
// The transform is evaluated at the end of the substep (like collider poses), since the grains
// node pulls the end-of-substep positions toward it.
//
// The node also writes `targetstiffness` (= stiffness) and `targetweight` (= weight) on its
// points when the attribute did not exist before the node first cooked (it owns it then, and
// points born later get the value too). An attribute authored elsewhere (a source file, another
// node) is left alone. Points outside the group keep targetstiffness 0: no pin.
#include <filesystem>
#include <omp.h>

#include <limits>

#include "engine/geometry_io.h"
#include "engine/node.h"
#include "engine/state_stream.h"
#include "nodes/common.h"
#include "engine/param_rows.h"
#include "nodes/register.h"

namespace grains {
namespace {

// Closest point to p on triangle abc (Ericson, Real-Time Collision Detection, §5.1.5).
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  Vec3 ab = b - a, ac = c - a, ap = p - a;
  float d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  Vec3 bp = p - b;
  float d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  float vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  Vec3 cp = p - c;
  float d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  float vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  float va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  float denom = 1.0f / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

enum Mode { kRest, kSurface };  // mode's menu

// the node's parameters (engine/param_rows.h)
#define TARGET_PARAMS(ROW)                                                                        \
  ROW(FLOAT, activation, 1, , "the node acts only while this is greater than 0")                 \
  ROW(STRING, group, "", , "act only on this point group of the stream (empty: the whole stream)") \
  ROW(MENU, mode, kRest, .menu_of({"rest", "surface"}),                                           \
      "rest: targetP = transformed rest position; surface: the closest point on the transformed mesh `file`") \
  ROW(STRING, file, "", , "PLY or OBJ mesh for mode \"surface\", relative to the graph")           \
  ROW(VECTOR, translate, (0, 0, 0), .unit("m"), "translation of the target transform")             \
  ROW(VECTOR, rotate, (0, 0, 0), .unit("deg"), "rotation, XYZ order, about the pivot")             \
  ROW(VECTOR, scale, (1, 1, 1), , "per-axis scale about the pivot")                               \
  ROW(FLOAT, uniform_scale, 1, , "uniform scale about the pivot, times `scale`")                  \
  ROW(VECTOR, pivot, (0, 0, 0), .unit("m"), "centre of rotation and scale")                        \
  ROW(FLOAT, stiffness, 1, .at_least(0),                                                          \
      "targetstiffness written on the points when the node owns it (scales the grains node's target_stiffness)") \
  ROW(FLOAT, weight, 1, .at_least(0),                                                             \
      "targetweight written on the points when the node owns it (scales the grains node's target_weight)")
GR_NODE_PARAMS(TargetParams, TARGET_PARAMS)

struct Transform {
  Pose rot;
  Vec3 translate, scale, pivot;
  explicit Transform(const TargetParams& p)
      : rot(Pose::from_trs({0, 0, 0}, p.rotate, 1.0f)),
        translate(p.translate),
        scale(p.scale * static_cast<float>(p.uniform_scale)),
        pivot(p.pivot) {}
  Vec3 apply(const Vec3& x) const {
    Vec3 d = x - pivot;
    return rot.rotate({d.x * scale.x, d.y * scale.y, d.z * scale.z}) + pivot + translate;
  }
};

class TargetNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    if (TargetParams::read(ctx.params).activation <= 0) return;
    ParticleStore& s = ctx.pts;
    // the transform at the end of the substep: a copy of the parameters evaluated there
    ParamSet end = ctx.params;
    if (ctx.vars) {
      ExprVars v = *ctx.vars;
      v.ST += ctx.time.dt;
      v.T += ctx.time.dt;
      v.SF = v.ST * ctx.time.fps;
      v.F = v.SF + 1;
      end.evaluate(v);
    }
    const TargetParams p = TargetParams::read(end);
    const std::string& group = p.group;
    const int32_t* g = group.empty() ? nullptr : s.i_if(group_attribute(group));
    if (!group.empty() && !g) return;

    if (first_) {
      owns_stiffness_ = !s.has("targetstiffness");
      owns_weight_ = !s.has("targetweight");
      first_ = false;
    }
    const bool surface = p.mode == kSurface;
    if (surface && mesh_.triangles.empty()) mesh_ = read_mesh(resolve_path(ctx.base_dir, p.file));
    const Transform X(p);
    if (surface) {
      world_.resize(mesh_.vertices.size());
      for (size_t k = 0; k < world_.size(); ++k) world_[k] = X.apply(mesh_.vertices[k]);
    }

    idx_.clear();
    for (uint32_t k : ctx.members)
      if (!g || g[k]) idx_.push_back(k);
    float* target = s.v3("targetP");
    const float* rest = surface ? nullptr : s.v3("rest");
    const float* P = s.v3("P");
    const long n = static_cast<long>(idx_.size());
#pragma omp parallel for schedule(static) num_threads(ctx.threads > 0 ? ctx.threads : omp_get_max_threads())
    for (long k = 0; k < n; ++k) {
      uint32_t i = idx_[k];
      store3(target, i, surface ? closest_on_mesh(load3(P, i)) : X.apply(load3(rest, i)));
    }
    if (owns_stiffness_) {
      float* ts = s.f("targetstiffness");
      for (uint32_t i : idx_) ts[i] = static_cast<float>(p.stiffness);
    }
    if (owns_weight_) {
      float* tw = s.f("targetweight");
      for (uint32_t i : idx_) tw[i] = static_cast<float>(p.weight);
    }
  }

  // whether the node made targetstiffness / targetweight itself at its first cook (the mesh is
  // read again when needed)
  void save_state(StateWriter& w) const override {
    w.section("target");
    w.value(first_);
    w.value(owns_stiffness_);
    w.value(owns_weight_);
  }
  void load_state(StateReader& r) override {
    r.section("target");
    r.value(first_);
    r.value(owns_stiffness_);
    r.value(owns_weight_);
  }

 private:
  // Brute force over the triangles: meant for the small models targets use (a few thousand
  // triangles); a grid or BVH would be the next step for big ones.
  Vec3 closest_on_mesh(const Vec3& x) const {
    float best = std::numeric_limits<float>::infinity();
    Vec3 out = x;
    for (const auto& t : mesh_.triangles) {
      Vec3 q = closest_on_triangle(x, world_[t[0]], world_[t[1]], world_[t[2]]);
      Vec3 dq = q - x;
      float d2 = dot(dq, dq);
      if (d2 < best) best = d2, out = q;
    }
    return out;
  }

  bool first_ = true, owns_stiffness_ = false, owns_weight_ = false;
  Mesh mesh_;
  std::vector<Vec3> world_;
  std::vector<uint32_t> idx_;
};

}  // namespace

void register_target_node() {
  NodeTypeInfo t;
  t.type = "target";
  t.doc = "Sets the pin target targetP: each point's rest position through an animated transform, "
          "or the closest point on a mesh surface (grains node target_weight/target_stiffness pull toward it).";
  t.params = TargetParams::decls();
  t.make = [] { return std::make_unique<TargetNode>(); };
  t.check = [](const ParamSet& params, const std::string& base) -> std::pair<std::string, std::string> {
    const TargetParams p = TargetParams::read(params);
    if (p.mode == kSurface) {
      if (p.file.empty()) return {"mode \"surface\" needs a `file`", "file"};
      std::string path = resolve_path(base, p.file);
      if (!std::filesystem::exists(path)) return {"file not found: " + path, "file"};
    }
    return {"", ""};
  };
  register_node_type(std::move(t));
}

}  // namespace grains
