// attribute: sets or creates a point attribute from a per-point expression, as Houdini users
// do with an attribute expression or a wrangle: `friction` by height, `pscale` at random by
// id, a `targetstiffness` only inside. The expression sees the node's time variables ($ST, $F,
// ...) and each point's own: $ID, $PT (its index), $NPT (the points of its stream), $AGE (s),
// $LIFE (age / the `life` attribute, 0 without it), $TX $TY $TZ (position), $VX $VY $VZ
// (velocity), and any attribute as @name (a float or int attribute) or @name_x, @name_y,
// @name_z (a vector's components). A vector attribute takes three expressions separated by
// commas, or one for all three. Values that are not finite stop the run, naming the point.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/expression.h"
#include "engine/node.h"
#include "engine/param_rows.h"
#include "engine/particles.h"
#include "nodes/register.h"

namespace grains {
namespace {

enum AttrKind { kFloat, kVector };

#define ATTRIBUTE_PARAMS(ROW)                                                                       \
  ROW(FLOAT, activation, 1, , "the node acts only while this is greater than 0")                   \
  ROW(STRING, attribute, "", , "the point attribute to set; made when missing")                     \
  ROW(MENU, type, kFloat, .menu_of({"float", "vector"}),                                            \
      "type of an attribute the points do not have yet and the known table does not name")         \
  ROW(STRING, value, "0", ,                                                                        \
      "per-point expression; a vector takes three separated by commas (or one for all). Point "   \
      "variables: $ID, $PT, "                                                                        \
      "$NPT, $AGE, $LIFE, $TX $TY $TZ, $VX $VY $VZ, @name and @name_x/_y/_z for any attribute")   \
  ROW(STRING, group, "", , "set it only on the points of this group (empty: every point)")
GR_NODE_PARAMS(AttributeParams, ATTRIBUTE_PARAMS)

// The value text split at the commas outside parentheses.
std::vector<std::string> split_top_level(const std::string& text) {
  std::vector<std::string> out(1);
  int depth = 0;
  for (char c : text) {
    if (c == '(') ++depth;
    if (c == ')') --depth;
    if (c == ',' && depth == 0) {
      out.emplace_back();
      continue;
    }
    out.back() += c;
  }
  return out;
}

// The @names an expression text uses, in order of first use.
std::vector<std::string> at_names(const std::string& text) {
  std::vector<std::string> out;
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] != '@') continue;
    size_t j = i + 1;
    while (j < text.size() && (std::isalnum(static_cast<unsigned char>(text[j])) || text[j] == '_'))
      ++j;
    std::string n = text.substr(i, j - i);
    if (n.size() > 1 && std::find(out.begin(), out.end(), n) == out.end()) out.push_back(n);
    i = j - 1;
  }
  return out;
}

// The point variables every expression sees, in this order in the slots
const char* const kPointVars[] = {"ID", "PT", "NPT", "AGE", "LIFE", "TX", "TY", "TZ", "VX", "VY", "VZ"};
constexpr size_t kPointVarCount = sizeof(kPointVars) / sizeof(kPointVars[0]);

// An attribute a @name reads: the attribute and the component (0 for scalars)
struct AtSource {
  std::string attribute;
  int component = 0;
};

// Which attribute and component `@name` means in `s` ("" when none)
AtSource resolve_at(const ParticleStore& s, const std::string& at) {
  const std::string name = at.substr(1);
  if (s.has(name)) {
    const Attribute* a = s.find(name);
    if (a->components() == 1) return {name, 0};
  }
  if (name.size() > 2 && name[name.size() - 2] == '_') {
    const char c = name.back();
    const std::string base = name.substr(0, name.size() - 2);
    const int comp = c == 'x' ? 0 : c == 'y' ? 1 : c == 'z' ? 2 : -1;
    if (comp >= 0 && s.has(base) && s.find(base)->components() == 3) return {base, comp};
  }
  return {};
}

// Compiled expressions with their variable slots, for one set of attribute names.
struct Compiled {
  std::string key;                    // the value text and the store's attribute names
  std::unique_ptr<double[]> slots;    // kPointVars, then one per @name
  std::vector<AtSource> at_sources;   // per @name, in slot order after kPointVars
  std::vector<Expression> exprs;      // 1 or 3
  // whether they read the positions ($TX $TY $TZ) and the velocities ($VX $VY $VZ): the store's
  // arrays are taken only then (a grains node may hold them: engine/particles.h)
  bool reads_P = false, reads_v = false;
};

// Compiles `text` (1 or `count` expressions) with the point variables bound to fresh slots and
// each @name to a slot of its own; `sources` resolves @names (null: any @name is accepted, to
// check the syntax at load).
Compiled compile(const std::string& text, size_t count, const ParticleStore* sources,
                 const std::vector<std::string>& channel_names) {
  Compiled c;
  const std::vector<std::string> parts = split_top_level(text);
  if (count == 1 && parts.size() != 1)
    throw ExprError("value \"" + text + "\": a float attribute takes one expression, not " +
                    std::to_string(parts.size()) + " separated by commas");
  if (count == 3 && parts.size() != 1 && parts.size() != 3)
    throw ExprError("value \"" + text + "\": a vector attribute takes one expression (for all "
                    "three components) or three separated by commas, not " +
                    std::to_string(parts.size()));
  const std::vector<std::string> ats = at_names(text);
  c.slots = std::make_unique<double[]>(kPointVarCount + ats.size());
  std::vector<std::pair<std::string, double*>> bound;
  for (size_t k = 0; k < kPointVarCount; ++k) {
    c.slots[k] = 0;
    bound.emplace_back(kPointVars[k], &c.slots[k]);
    bound.emplace_back(std::string("$") + kPointVars[k], &c.slots[k]);
  }
  for (size_t k = 0; k < ats.size(); ++k) {
    c.slots[kPointVarCount + k] = 0;
    bound.emplace_back(ats[k], &c.slots[kPointVarCount + k]);
    if (!sources) continue;
    AtSource src = resolve_at(*sources, ats[k]);
    if (src.attribute.empty())
      throw ExprError("value \"" + text + "\": " + ats[k] + " names no attribute of the points");
    c.at_sources.push_back(src);
  }
  for (const std::string& part : parts) c.exprs.emplace_back(part, channel_names, bound);
  auto reads = [&](size_t first) {
    for (const Expression& e : c.exprs)
      for (size_t k = first; k < first + 3; ++k)
        if (e.uses(kPointVars[k]) || e.uses(std::string("$") + kPointVars[k])) return true;
    return false;
  };
  c.reads_P = reads(5);  // TX TY TZ
  c.reads_v = reads(8);  // VX VY VZ
  return c;
}

class AttributeNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    const AttributeParams p = AttributeParams::read(ctx.params);
    if (p.activation <= 0) return;
    ParticleStore& s = ctx.pts;
    // the attribute, made when missing: a known one with its own type, else `type`
    if (!s.has(p.attribute)) {
      const AttribDefault* known = find_known_attribute(p.attribute);
      s.add(p.attribute, known ? known->type : (p.type == kVector ? AttribType::Vec3 : AttribType::Float));
    }
    Attribute& dst = *s.find(p.attribute);
    const size_t comps = static_cast<size_t>(dst.components());
    std::string key = p.value + "|" + std::to_string(comps);
    for (const std::string& n : at_names(p.value)) {
      const AtSource src = resolve_at(s, n);
      key += "|" + src.attribute + ":" + std::to_string(src.component);
    }
    if (key != compiled_.key) {
      try {
        compiled_ = compile(p.value, comps, &s, {});
      } catch (const ExprError& e) {
        throw std::runtime_error("frame " + std::to_string(ctx.time.frame) + ", node '" +
                                 ctx.node_name + "', parameter 'value': " + e.what());
      }
      compiled_.key = key;
    }
    const std::string group = p.group.empty() ? std::string() : group_attribute(p.group);
    const int32_t* in_group = group.empty() ? nullptr : s.i_if(group);
    if (!group.empty() && !in_group) return;  // no point is in the group yet
    const float* P = compiled_.reads_P ? s.v3_if("P") : nullptr;
    const float* v = compiled_.reads_v ? s.v3_if("v") : nullptr;
    const float* age = s.f_if("age");
    const float* life = s.f_if("life");
    const int32_t* id = s.i_if("id");
    double* slot = compiled_.slots.get();
    slot[2] = static_cast<double>(ctx.members.size());
    // the attributes @names read, looked up once
    struct Read {
      const Attribute* a;
      int component;
    };
    std::vector<Read> reads;
    for (const AtSource& src : compiled_.at_sources) reads.push_back({s.find(src.attribute), src.component});
    double out[3] = {0, 0, 0};
    const ExprVars no_vars;
    for (uint32_t k : ctx.members) {
      if (in_group && !in_group[k]) continue;
      slot[0] = id ? id[k] : static_cast<double>(k);
      slot[1] = static_cast<double>(k);
      slot[3] = age ? age[k] : 0.0;
      slot[4] = age && life && life[k] > 0 ? age[k] / life[k] : 0.0;
      for (int c = 0; c < 3; ++c) {
        slot[5 + c] = P ? P[3 * k + c] : 0.0;
        slot[8 + c] = v ? v[3 * k + c] : 0.0;
      }
      for (size_t r = 0; r < reads.size(); ++r) {
        const Attribute& a = *reads[r].a;
        const size_t at = k * static_cast<size_t>(a.components()) + static_cast<size_t>(reads[r].component);
        slot[kPointVarCount + r] = a.type == AttribType::Int ? a.i[at] : a.f[at];
      }
      for (size_t c = 0; c < comps; ++c) {
        // one expression for a vector sets all three components
        out[c] = c < compiled_.exprs.size() ? compiled_.exprs[c].eval(ctx.vars ? *ctx.vars : no_vars)
                                            : out[0];
        if (!std::isfinite(out[c]) || (dst.type != AttribType::Int && !std::isfinite(float(out[c])))) {
          char buf[96];
          std::snprintf(buf, sizeof buf, "%g", out[c]);
          throw std::runtime_error("frame " + std::to_string(ctx.time.frame) + ", substep " +
                                   std::to_string(ctx.time.substep + 1) + ", node '" +
                                   ctx.node_name + "': point id " +
                                   std::to_string(id ? id[k] : int32_t(k)) + ": '" + p.attribute +
                                   "' would be " + buf + ", not finite (parameter 'value': " + p.value + ")");
        }
      }
      if (dst.type == AttribType::Int) {
        dst.i[k] = static_cast<int32_t>(std::lround(std::fmax(-2147483648.0, std::fmin(2147483647.0, out[0]))));
      } else {
        for (size_t c = 0; c < comps; ++c) dst.f[k * comps + c] = static_cast<float>(out[c]);
      }
    }
  }

 private:
  Compiled compiled_;
};

bool plain_name(const std::string& n) {
  if (n.empty() || std::isdigit(static_cast<unsigned char>(n[0]))) return false;
  for (char c : n)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') return false;
  return true;
}

// names the node must not write: the solver's bookkeeping
bool protected_attribute(const std::string& name) {
  return name == "id" || name == "streamid" || name == "ispbd" || name.rfind("group_", 0) == 0;
}

}  // namespace

void register_attribute_node() {
  NodeTypeInfo t;
  t.type = "attribute";
  t.doc = "Sets or creates a point attribute from a per-point expression (point variables $ID, $PT, $NPT, $AGE, $LIFE, $TX..$VZ, @name).";
  t.params = AttributeParams::decls();
  t.make = [] { return std::make_unique<AttributeNode>(); };
  t.check = [](const ParamSet& params, const std::string&) -> std::pair<std::string, std::string> {
    const AttributeParams p = AttributeParams::read(params);
    if (p.attribute.empty()) return {"needs the name of the attribute to set", "attribute"};
    if (protected_attribute(p.attribute))
      return {"'" + p.attribute + "' is kept by the engine and cannot be set", "attribute"};
    if (!plain_name(p.attribute))
      return {"'" + p.attribute + "' is not an attribute name (letters, digits and _, not first a digit)",
              "attribute"};
    if (!p.group.empty())
      if (std::string bad = group_name_problem(p.group); !bad.empty()) return {bad, "group"};
    const AttribDefault* known = find_known_attribute(p.attribute);
    const size_t comps = known ? (known->type == AttribType::Vec3 ? 3 : 1) : (p.type == kVector ? 3 : 1);
    try {
      compile(p.value, comps, nullptr, {});
    } catch (const ExprError& e) {
      return {e.what(), "value"};
    }
    return {"", ""};
  };
  t.adds_attributes = [](const ParamSet& params) {
    return std::vector<std::string>{AttributeParams::read(params).attribute};
  };
  register_node_type(std::move(t));
}

}  // namespace grains
