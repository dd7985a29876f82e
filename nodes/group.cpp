// group: puts points of the node's stream into a named point group by region (box, sphere) or
// by comparing an attribute with a value.
#include <cmath>

#include "engine/node.h"
#include "nodes/common.h"
#include "engine/param_rows.h"
#include "nodes/register.h"

namespace grains {
namespace {

// the menus' choices, in their order
enum Rule { kRuleBox, kRuleSphere, kRuleAttribute };
enum Compare { kLess, kLessEqual, kGreater, kGreaterEqual, kEqual, kNotEqual };
enum Operation { kReplace, kAdd, kIntersect, kSubtract };

// the node's parameters (engine/param_rows.h)
#define GROUP_PARAMS(ROW)                                                                   \
  ROW(FLOAT, activation, 1, , "the node acts only while this is greater than 0")           \
  ROW(STRING, group_name, "group1", , "name of the point group")                            \
  ROW(MENU, rule, kRuleBox, .menu_of({"box", "sphere", "attribute"}), "membership test")    \
  ROW(VECTOR, center, (0, 0, 0), .unit("m"), "centre of the box or sphere")                 \
  ROW(VECTOR, size, (1, 1, 1), .unit("m"), "full extents of the box")                       \
  ROW(FLOAT, radius, 0.5, .positive().unit("m"), "radius of the sphere")                    \
  ROW(STRING, attribute, "", , "attribute compared (vector components as NAME_x)")          \
  ROW(MENU, compare, kGreater, .menu_of({"<", "<=", ">", ">=", "==", "!="}),                \
      "comparison with `value`")                                                            \
  ROW(FLOAT, value, 0, , "value the attribute is compared with")                            \
  ROW(MENU, operation, kReplace, .menu_of({"replace", "add", "intersect", "subtract"}),     \
      "how the test combines with existing membership")
GR_NODE_PARAMS(GroupParams, GROUP_PARAMS)

bool compare(int op, double a, double b) {
  switch (op) {
    case kLess: return a < b;
    case kLessEqual: return a <= b;
    case kGreater: return a > b;
    case kGreaterEqual: return a >= b;
    case kEqual: return a == b;
    default: return a != b;
  }
}

class GroupNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    const GroupParams p = GroupParams::read(ctx.params);
    if (p.activation <= 0) return;
    ParticleStore& s = ctx.pts;
    const std::string& name = p.group_name;
    const int rule = p.rule, op = p.operation, cmp = p.compare;
    const Region region = rule == kRuleSphere ? Region::Sphere : Region::Box;
    int32_t* g = s.i(group_attribute(name));
    const float* P = s.v3("P");
    const Attribute* attr = nullptr;
    int comp = 0;
    if (rule == kRuleAttribute) {
      std::string an = p.attribute;
      auto us = an.rfind('_');
      attr = s.find(an);
      if (!attr && us != std::string::npos && an.size() == us + 2) {  // NAME_x, NAME_y, NAME_z
        attr = s.find(an.substr(0, us));
        comp = an.back() - 'x';
        if (attr && (attr->type != AttribType::Vec3 || comp < 0 || comp > 2)) attr = nullptr;
      }
      if (!attr) return;  // no point has the attribute yet: nothing matches
    }
    Vec3 c = p.center, size = p.size;
    float radius = static_cast<float>(p.radius);
    double value = p.value;
    for (uint32_t k : ctx.members) {
      bool hit;
      if (rule == kRuleAttribute) {
        double a = attr->type == AttribType::Int ? attr->i[k]
                   : attr->type == AttribType::Float ? attr->f[k]
                                                     : attr->f[3 * k + comp];
        hit = compare(cmp, a, value);
      } else {
        hit = inside_region(region, c, size, radius, load3(P, k));
      }
      if (op == kReplace) g[k] = hit ? 1 : 0;
      else if (op == kAdd) g[k] = (g[k] || hit) ? 1 : 0;
      else if (op == kIntersect) g[k] = (g[k] && hit) ? 1 : 0;
      else g[k] = (g[k] && !hit) ? 1 : 0;  // subtract
    }
  }
};

}  // namespace

void register_group_node() {
  NodeTypeInfo t;
  t.type = "group";
  t.doc = "Puts points into a named group by region or attribute comparison, every substep.";
  t.params = GroupParams::decls();
  t.make = [] { return std::make_unique<GroupNode>(); };
  t.check = [](const ParamSet& params, const std::string&) -> std::pair<std::string, std::string> {
    const GroupParams p = GroupParams::read(params);
    if (std::string bad = group_name_problem(p.group_name); !bad.empty())
      return {bad, "group_name"};
    if (p.rule == kRuleAttribute && p.attribute.empty())
      return {"rule \"attribute\" needs an `attribute`", "attribute"};
    return {"", ""};
  };
  t.adds_attributes = [](const ParamSet& p) {
    return std::vector<std::string>{group_attribute(GroupParams::read(p).group_name)};
  };
  register_node_type(std::move(t));
}

}  // namespace grains
