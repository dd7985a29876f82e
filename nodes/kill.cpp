// kill: deletes the stream's points inside (or outside) a region.
#include "engine/node.h"
#include "nodes/common.h"
#include "nodes/register.h"

namespace grains {
namespace {

class KillNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    const ParamSet& p = ctx.params;
    if (p.f("activation") <= 0) return;
    ParticleStore& s = ctx.pts;
    const float* P = s.v3("P");
    Vec3 c = p.v3("center"), size = p.v3("size");
    float radius = static_cast<float>(p.f("radius"));
    bool invert = p.b("invert");
    const auto shape = static_cast<Region>(p.choice("shape"));  // the menu is in Region's order
    std::vector<uint8_t> dead(s.size(), 0);
    bool any = false;
    for (uint32_t k : ctx.members) {
      bool in = inside_region(shape, c, size, radius, load3(P, k));
      if (in != invert) dead[k] = 1, any = true;
    }
    if (any) s.remove_points(dead);
  }
};

}  // namespace

void register_kill_node() {
  NodeTypeInfo t;
  t.type = "kill";
  t.doc = "Deletes points inside a region (or outside it, with invert).";
  t.params = {
      ParamDecl::Float("activation", 1, "the node acts only while this is greater than 0"),
      ParamDecl::Menu("shape", {"box", "sphere", "cylinder"}, "box",
                      "region shape; cylinder: vertical axis through center, radius, height size.y"),
      ParamDecl::Vector("center", {0, -10, 0}, "centre of the region").unit("m"),
      ParamDecl::Vector("size", {100, 10, 100}, "full extents of the box; size.y is the cylinder's height").unit("m"),
      ParamDecl::Float("radius", 1, "radius of the sphere or cylinder").positive().unit("m"),
      ParamDecl::Toggle("invert", false, "kill the points outside the region instead"),
  };
  t.make = [] { return std::make_unique<KillNode>(); };
  register_node_type(std::move(t));
}

}  // namespace grains
