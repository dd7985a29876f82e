#include "engine/params.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace grains {

const char* param_type_name(ParamType t) {
  switch (t) {
    case ParamType::Float: return "float";
    case ParamType::Int: return "int";
    case ParamType::Toggle: return "toggle";
    case ParamType::Vec3: return "vector";
    case ParamType::String: return "string";
    case ParamType::Menu: return "menu";
    case ParamType::StringList: return "string list";
  }
  return "?";
}

ParamDecl ParamDecl::Float(std::string name, double def, std::string doc) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::Float;
  d.def[0] = def;
  d.doc = std::move(doc);
  return d;
}
ParamDecl ParamDecl::Int(std::string name, int def, std::string doc) {
  ParamDecl d = Float(std::move(name), def, std::move(doc));
  d.type = ParamType::Int;
  return d;
}
ParamDecl ParamDecl::Toggle(std::string name, bool def, std::string doc) {
  ParamDecl d = Float(std::move(name), def ? 1 : 0, std::move(doc));
  d.type = ParamType::Toggle;
  return d;
}
ParamDecl ParamDecl::Vector(std::string name, Vec3 def, std::string doc) {
  ParamDecl d = Float(std::move(name), 0, std::move(doc));
  d.type = ParamType::Vec3;
  d.def[0] = def.x;
  d.def[1] = def.y;
  d.def[2] = def.z;
  return d;
}
ParamDecl ParamDecl::String(std::string name, std::string def, std::string doc) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::String;
  d.def_string = std::move(def);
  d.doc = std::move(doc);
  return d;
}
ParamDecl ParamDecl::Menu(std::string name, std::vector<std::string> choices, std::string def,
                          std::string doc) {
  ParamDecl d = String(std::move(name), std::move(def), std::move(doc));
  d.type = ParamType::Menu;
  d.menu = std::move(choices);
  return d;
}
ParamDecl ParamDecl::List(std::string name, std::string doc) {
  ParamDecl d = String(std::move(name), "", std::move(doc));
  d.type = ParamType::StringList;
  return d;
}

ParamDecl ParamDecl::Choice(std::string name, int def, std::string doc) {
  ParamDecl d = Menu(std::move(name), {}, "", std::move(doc));
  d.def[0] = def;
  return d;
}
ParamDecl& ParamDecl::menu_of(std::vector<std::string> choices) {
  type = ParamType::Menu;
  menu = std::move(choices);
  const int k = static_cast<int>(def[0]);
  if (k < 0 || k >= static_cast<int>(menu.size()))
    throw std::logic_error("'" + name + "': default choice " + std::to_string(k) + " is not in its menu");
  def_string = menu[k];
  return *this;
}

static std::string num(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

std::string ParamDecl::default_text() const {
  switch (type) {
    case ParamType::Float: return num(def[0]);
    case ParamType::Int: return num(def[0]);
    case ParamType::Toggle: return def[0] != 0 ? "true" : "false";
    case ParamType::Vec3: {
      std::string out(1, '[');
      out.append(num(def[0])).append(", ").append(num(def[1])).append(", ").append(num(def[2]));
      out.push_back(']');
      return out;
    }
    case ParamType::String:
    case ParamType::Menu: {
      std::string out(1, '"');  // appended, not concatenated: GCC 12 warns falsely on a + b + c
      out.append(def_string).push_back('"');
      return out;
    }
    case ParamType::StringList: return "[]";
  }
  return "";
}

// a number as the user would write it: integers whole, others to float precision and more
static std::string exact(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.15g", v);
  return buf;
}

std::string ParamDecl::value_error(double v) const {
  if (!std::isfinite(v)) return "'" + name + "' must be a finite number, got " + exact(v);
  // an integer's value must fit an int (2^31 - 1), else it would wrap where it is read
  constexpr double kIntMax = 2147483647.0;
  if (type == ParamType::Int && !(std::fabs(v) <= kIntMax))
    return "'" + name + "' must be at most " + exact(kIntMax) + " in size, got " + exact(v);
  // positions, forces and most other quantities are floats in the solver
  constexpr double kFloatMax = 3.4028234663852886e38;
  if ((type == ParamType::Float || type == ParamType::Vec3) && !(std::fabs(v) <= kFloatMax))
    return "'" + name + "' must be within the float range (3.4e38 in size), got " + exact(v);
  // ... and not so small that it becomes 0 as a float: a separation of 1e-300 passed "greater
  // than 0" and made grains of radius 0, a mass of 1e-300 an anchor
  if ((type == ParamType::Float || type == ParamType::Vec3) && v != 0 &&
      static_cast<float>(v) == 0.0f)
    return "'" + name + "' must be 0 or at least 1.4e-45 in size (the smallest float), got " +
           exact(v);
  if (has_min && (min_exclusive ? !(v > min) : !(v >= min)))
    return "'" + name + "' must be " + (min_exclusive ? "greater than " : "at least ") +
           exact(min) + ", got " + exact(v);
  if (has_max && !(v <= max))
    return "'" + name + "' must be at most " + exact(max) + ", got " + exact(v);
  return "";
}

std::vector<std::string> ParamDecl::channel_names() const {
  if (type == ParamType::Vec3) return {name + "x", name + "y", name + "z"};
  if (animatable()) return {name};
  return {};
}

ParamSet::ParamSet(const std::vector<ParamDecl>& decls,
                   const std::map<std::string, ParamValue>& given) {
  std::vector<std::string> all_channels;
  for (const auto& d : decls)
    for (auto& c : d.channel_names()) all_channels.push_back(c);
  for (const auto& d : decls) {
    Entry e;
    e.decl = &d;
    auto it = given.find(d.name);
    if (it != given.end()) authored_[d.name] = true;
    if (d.animatable()) {
      int n = d.type == ParamType::Vec3 ? 3 : 1;
      for (int k = 0; k < n; ++k) {
        if (it == given.end()) {
          e.channels.push_back(Channel::constant(d.def[k]));
          continue;
        }
        const ChannelSource& src = it->second.channels.at(k);
        switch (src.kind) {
          case ChannelSource::Kind::Constant: e.channels.push_back(Channel::constant(src.value)); break;
          case ChannelSource::Kind::Expression:
            e.channels.push_back(Channel::expression(src.text, all_channels));
            break;
          case ChannelSource::Kind::Keys: e.channels.push_back(Channel::keyframes(src.keys)); break;
        }
      }
      for (int k = 0; k < n; ++k) e.value[k] = d.def[k];
    } else if (d.type == ParamType::StringList) {
      if (it != given.end()) e.list = it->second.list;
    } else {
      e.text = it != given.end() ? it->second.text : d.def_string;
      if (d.type == ParamType::Menu) {
        auto at = std::find(d.menu.begin(), d.menu.end(), e.text);
        // the loader refused any other text
        if (at == d.menu.end()) throw std::logic_error("'" + d.name + "': \"" + e.text + "\" is not in its menu");
        e.choice = static_cast<int>(at - d.menu.begin());
      }
    }
    entries_[d.name] = std::move(e);
  }
  for (auto& c : all_channels) previous_[c] = 0.0;
}

void ParamSet::evaluate(ExprVars vars) {
  vars.channels = &previous_;
  for (auto& [name, e] : entries_) {
    for (size_t k = 0; k < e.channels.size(); ++k) {
      double v = e.channels[k].eval(vars);
      if (e.decl->type == ParamType::Int) v = std::round(v);
      // constants were checked when the graph loaded; expressions and keys are checked here,
      // each time they are evaluated
      if (!e.channels[k].is_constant()) {
        const std::string bad = e.decl->value_error(v);
        if (!bad.empty()) throw ParamRangeError(e.decl->name, bad);
      }
      if (e.decl->type == ParamType::Toggle) v = v != 0 ? 1 : 0;
      e.value[k] = v;
    }
  }
  // previous values become visible to the next evaluation only
  for (auto& [name, e] : entries_) {
    auto names = e.decl->channel_names();
    for (size_t k = 0; k < names.size(); ++k) previous_[names[k]] = e.value[k];
  }
}

const ParamSet::Entry& ParamSet::get(const std::string& name, ParamType expect) const {
  auto it = entries_.find(name);
  if (it == entries_.end()) throw std::logic_error("no parameter '" + name + "' declared");
  if (it->second.decl->type != expect)
    throw std::logic_error("parameter '" + name + "' is " +
                           param_type_name(it->second.decl->type) + ", read as " +
                           param_type_name(expect));
  return it->second;
}

double ParamSet::f(const std::string& name) const { return get(name, ParamType::Float).value[0]; }
int ParamSet::i(const std::string& name) const {
  const double v = get(name, ParamType::Int).value[0];
  // checked where the value was set (value_error): in range here
  if (!(std::fabs(v) <= 2147483647.0)) throw std::logic_error("'" + name + "' is beyond int");
  return static_cast<int>(v);
}
bool ParamSet::b(const std::string& name) const {
  return get(name, ParamType::Toggle).value[0] != 0;
}
Vec3 ParamSet::v3(const std::string& name) const {
  const Entry& e = get(name, ParamType::Vec3);
  return {static_cast<float>(e.value[0]), static_cast<float>(e.value[1]),
          static_cast<float>(e.value[2])};
}
const std::string& ParamSet::s(const std::string& name) const {
  auto it = entries_.find(name);
  if (it == entries_.end()) throw std::logic_error("no parameter '" + name + "' declared");
  if (it->second.decl->type != ParamType::String && it->second.decl->type != ParamType::Menu)
    throw std::logic_error("parameter '" + name + "' is not a string");
  return it->second.text;
}
int ParamSet::choice(const std::string& name) const { return get(name, ParamType::Menu).choice; }
const std::vector<std::string>& ParamSet::list(const std::string& name) const {
  return get(name, ParamType::StringList).list;
}
bool ParamSet::is_animated(const std::string& name) const {
  auto it = entries_.find(name);
  if (it == entries_.end()) return false;
  for (const auto& c : it->second.channels)
    if (!c.is_constant()) return true;
  return false;
}

}  // namespace grains
