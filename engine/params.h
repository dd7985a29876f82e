// Parameter declarations: each node type declares its parameters once (name, type, default,
// range, units, one-line meaning, the point attribute that scales it). The validator, `grains
// nodes`, the docs and the conformance tests all read these tables.
#pragma once
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/expression.h"
#include "engine/vec3.h"

namespace grains {

enum class ParamType {
  Float,       // number, expression or keyframes
  Int,         // integer number or expression (rounded)
  Toggle,      // true/false, 0/1 or expression (nonzero = on)
  Vec3,        // [x, y, z], each component a number, expression or keyframes
  String,      // free text (file paths, group names)
  Menu,        // one of `menu`
  StringList,  // array of strings (e.g. collider names)
};
const char* param_type_name(ParamType t);

struct ParamDecl {
  std::string name;
  ParamType type = ParamType::Float;
  double def[3] = {0, 0, 0};
  std::string def_string;
  std::vector<std::string> menu;  // Menu choices; def_string is the default
  bool has_min = false, has_max = false;
  bool min_exclusive = false;  // the value must be strictly greater than min
  double min = 0, max = 0;
  std::string units;
  std::string doc;
  std::string scale_attribute;  // point attribute that scales the value, if any

  // factories
  static ParamDecl Float(std::string name, double def, std::string doc);
  static ParamDecl Int(std::string name, int def, std::string doc);
  static ParamDecl Toggle(std::string name, bool def, std::string doc);
  static ParamDecl Vector(std::string name, Vec3 def, std::string doc);
  static ParamDecl String(std::string name, std::string def, std::string doc);
  static ParamDecl Menu(std::string name, std::vector<std::string> choices, std::string def,
                        std::string doc);
  static ParamDecl List(std::string name, std::string doc);
  // a menu whose default is its choice number def (the choices come with menu_of): for tables
  // that give the default as the enum value the node reads with ParamSet::choice
  static ParamDecl Choice(std::string name, int def, std::string doc);
  // modifiers
  ParamDecl& range(double lo, double hi) { has_min = has_max = true; min = lo; max = hi; return *this; }
  ParamDecl& at_least(double lo) { has_min = true; min = lo; return *this; }
  ParamDecl& positive() { has_min = true; min = 0; min_exclusive = true; return *this; }
  ParamDecl& unit(std::string u) { units = std::move(u); return *this; }
  ParamDecl& scaled_by(std::string a) { scale_attribute = std::move(a); return *this; }
  // a Choice's menu; its default becomes the choice numbered def[0]
  ParamDecl& menu_of(std::vector<std::string> choices);

  bool animatable() const {
    return type == ParamType::Float || type == ParamType::Int || type == ParamType::Toggle ||
           type == ParamType::Vec3;
  }
  std::string default_text() const;
  // What is wrong with v as this parameter's value ("" when nothing): not a finite number, an
  // integer beyond int, a float beyond float, or outside the declared range. The loader says it of a literal, the
  // evaluation of a value from an expression or keyframes (ParamRangeError).
  std::string value_error(double v) const;
  // channel names this parameter contributes as local variables (name, or namex namey namez)
  std::vector<std::string> channel_names() const;
};

// A value an expression or keyframes gave a parameter that its declaration does not allow; the
// simulation names the node, the frame and the graph file (the loader's message for a literal).
struct ParamRangeError : std::runtime_error {
  ParamRangeError(std::string param_name, const std::string& message)
      : std::runtime_error(message), param(std::move(param_name)) {}
  std::string param;
};

// A parameter as authored in the graph, validated against its declaration. Numeric channels
// keep their source (number, expression text or keyframes) and are compiled per node instance.
struct ChannelSource {
  enum class Kind { Constant, Expression, Keys } kind = Kind::Constant;
  double value = 0;
  std::string text;
  Keyframes keys;
};
struct ParamValue {
  std::vector<ChannelSource> channels;  // 1 or 3 for animatable types
  std::string text;                     // String / Menu
  std::vector<std::string> list;        // StringList
};

// A node's parameters evaluated at one moment, with previous values kept for `$channel`.
class ParamSet {
 public:
  ParamSet() = default;
  // decls: the node type's table; given: authored values (missing ones take the default).
  ParamSet(const std::vector<ParamDecl>& decls, const std::map<std::string, ParamValue>& given);
  // Evaluates every channel for this moment. Expressions read vars + the previous values.
  void evaluate(ExprVars vars);

  double f(const std::string& name) const;
  int i(const std::string& name) const;
  bool b(const std::string& name) const;
  Vec3 v3(const std::string& name) const;
  const std::string& s(const std::string& name) const;
  // a menu's choice as its number in the declaration's menu (resolved when the set is made,
  // so nodes compare enums, not strings)
  int choice(const std::string& name) const;
  const std::vector<std::string>& list(const std::string& name) const;
  bool is_animated(const std::string& name) const;
  bool authored(const std::string& name) const { return authored_.count(name) != 0; }

 private:
  struct Entry {
    const ParamDecl* decl = nullptr;
    std::vector<Channel> channels;
    double value[3] = {0, 0, 0};
    std::string text;
    int choice = 0;  // Menu: text's number in decl->menu
    std::vector<std::string> list;
  };
  const Entry& get(const std::string& name, ParamType expect) const;
  std::map<std::string, Entry> entries_;
  std::map<std::string, double> previous_;  // channel name → value at the last evaluation
  std::map<std::string, bool> authored_;
};

}  // namespace grains
