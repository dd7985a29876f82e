// force: adds a uniform force and drag to the `force` attribute of the stream's points.
#include "engine/node.h"
#include "nodes/register.h"

namespace grains {
namespace {

class ForceNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    const ParamSet& p = ctx.params;
    if (p.f("activation") <= 0) return;
    ParticleStore& s = ctx.pts;
    Vec3 force = p.v3("force"), wind = p.v3("wind");
    float drag = static_cast<float>(p.f("drag"));
    bool per_mass = p.b("ignore_mass");
    const std::string& group = p.s("group");
    float* F = s.v3("force");
    const float* v = s.v3("v");
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
  t.params = {
      ParamDecl::Float("activation", 1, "the node acts only while this is greater than 0"),
      ParamDecl::String("group", "", "act only on this point group (empty: the whole stream)"),
      ParamDecl::Vector("force", {0, 0, 0}, "uniform force").unit("N"),
      ParamDecl::Toggle("ignore_mass", false,
                        "multiply force and drag by each point's mass, so `force` is an acceleration (gravity)"),
      ParamDecl::Float("drag", 0, "drag coefficient: force -= drag * (v - wind)").at_least(0).unit("kg/s"),
      ParamDecl::Vector("wind", {0, 0, 0}, "velocity drag pulls towards").unit("m/s"),
  };
  t.make = [] { return std::make_unique<ForceNode>(); };
  register_node_type(std::move(t));
}

}  // namespace grains
