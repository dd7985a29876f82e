// kill: deletes the stream's points inside (or outside) a region.
#include "engine/node.h"
#include "nodes/common.h"
#include "engine/param_rows.h"
#include "nodes/register.h"

namespace grains {
namespace {

// the node's parameters (engine/param_rows.h); shape's menu is in Region's order
#define KILL_PARAMS(ROW)                                                                    \
  ROW(FLOAT, activation, 1, , "the node acts only while this is greater than 0")           \
  ROW(MENU, shape, 0, .menu_of({"box", "sphere", "cylinder"}),                              \
      "region shape; cylinder: vertical axis through center, radius, height size.y")        \
  ROW(VECTOR, center, (0, -10, 0), .unit("m"), "centre of the region")                      \
  ROW(VECTOR, size, (100, 10, 100), .unit("m"),                                             \
      "full extents of the box; size.y is the cylinder's height")                           \
  ROW(FLOAT, radius, 1, .positive().unit("m"), "radius of the sphere or cylinder")          \
  ROW(TOGGLE, invert, false, , "kill the points outside the region instead")
GR_NODE_PARAMS(KillParams, KILL_PARAMS)

class KillNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    const KillParams p = KillParams::read(ctx.params);
    if (p.activation <= 0) return;
    ParticleStore& s = ctx.pts;
    const float* P = s.v3("P");
    Vec3 c = p.center, size = p.size;
    float radius = static_cast<float>(p.radius);
    bool invert = p.invert;
    const auto shape = static_cast<Region>(p.shape.index);
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
  t.params = KillParams::decls();
  t.make = [] { return std::make_unique<KillNode>(); };
  register_node_type(std::move(t));
}

}  // namespace grains
