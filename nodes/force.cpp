// force: adds a uniform force and drag to the `force` attribute of the stream's points.
#include "engine/node.h"
#include "engine/param_rows.h"
#include "nodes/register.h"

namespace grains {
namespace {

// the node's parameters (engine/param_rows.h)
#define FORCE_PARAMS(ROW)                                                                     \
  ROW(FLOAT, activation, 1, , "the node acts only while this is greater than 0")             \
  ROW(STRING, group, "", , "act only on this point group (empty: the whole stream)")          \
  ROW(VECTOR, force, (0, 0, 0), .unit("N"), "uniform force")                                  \
  ROW(TOGGLE, ignore_mass, false, ,                                                           \
      "multiply force and drag by each point's mass, so `force` is an acceleration (gravity)") \
  ROW(FLOAT, drag, 0, .at_least(0).unit("kg/s"), "drag coefficient: force -= drag * (v - wind)") \
  ROW(VECTOR, wind, (0, 0, 0), .unit("m/s"), "velocity drag pulls towards")
GR_NODE_PARAMS(ForceParams, FORCE_PARAMS)

class ForceNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    const ForceParams p = ForceParams::read(ctx.params);
    if (p.activation <= 0) return;
    ParticleStore& s = ctx.pts;
    Vec3 force = p.force, wind = p.wind;
    float drag = static_cast<float>(p.drag);
    bool per_mass = p.ignore_mass;
    const std::string& group = p.group;
    float* F = s.v3("force");
    const float* v = drag != 0 ? s.v3("v") : nullptr;  // read only for drag (held: particles.h)
    const float* m = s.f("mass");
    const int32_t* g = group.empty() ? nullptr : s.i_if(group_attribute(group));
    if (!group.empty() && !g) return;  // the group does not exist yet: no member
    for (uint32_t k : ctx.members) {
      if (g && !g[k]) continue;
      float scale = per_mass ? m[k] : 1.0f;
      Vec3 f = force * scale;
      if (drag != 0) f -= (load3(v, k) - wind) * (drag * scale);
      store3(F, k, load3(F, k) + f);
    }
  }
};

}  // namespace

void register_force_node() {
  NodeTypeInfo t;
  t.type = "force";
  t.doc = "Adds a uniform force and drag towards a wind velocity.";
  t.params = ForceParams::decls();
  t.make = [] { return std::make_unique<ForceNode>(); };
  register_node_type(std::move(t));
}

}  // namespace grains
