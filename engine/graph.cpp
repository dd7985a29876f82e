#include "engine/graph.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "engine/geometry_io.h"

namespace grains {

using json = nlohmann::json;

namespace {

// A message that quotes a bad value quotes at most its start and its end: an unknown type or
// menu entry a megabyte long made a megabyte of error
std::string shortened(std::string m) {
  constexpr size_t kMost = 1000, kKept = 480;
  if (m.size() <= kMost) return m;
  const size_t cut = m.size() - 2 * kKept;
  return m.substr(0, kKept) + " ... [" + std::to_string(cut) + " characters left out] ... " +
         m.substr(m.size() - kKept);
}

}  // namespace

LoadError::LoadError(std::string f, std::string p, std::string m)
    : std::runtime_error(shortened(f) + ": " + (p.empty() ? "" : shortened(p) + ": ") +
                         shortened(m)),
      file(std::move(f)),
      pointer(std::move(p)),
      message(std::move(m)) {}

int Graph::find(const std::string& node_name) const {
  for (size_t k = 0; k < nodes.size(); ++k)
    if (nodes[k].name == node_name) return static_cast<int>(k);
  return -1;
}

Override parse_override(const std::string& text) {
  auto eq = text.find('=');
  auto dot = text.find('.');
  if (eq == std::string::npos || dot == std::string::npos || dot > eq || dot == 0 || dot + 1 == eq)
    throw LoadError("--set", "", "'" + text + "' is not NODE.PARAM=VALUE");
  return {text.substr(0, dot), text.substr(dot + 1, eq - dot - 1), text.substr(eq + 1)};
}

namespace {

std::string type_of(const json& j) {
  if (j.is_null()) return "null";
  if (j.is_boolean()) return "a boolean";
  if (j.is_number()) return "a number";
  if (j.is_string()) return "a string";
  if (j.is_array()) return "an array";
  return "an object";
}

// Names that become folder names (a solver's output folder, a graph's default output folder)
// must be plain, so that nothing is written outside the folder the user named. Returns what is
// wrong, or "".
std::string plain_name_problem(const std::string& what, const std::string& name) {
  bool plain = !name.empty() && name.size() <= 100 && name[0] != '.' && name[0] != '-';
  for (char c : name)
    plain = plain && (std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.');
  if (plain) return "";
  return "a " + what + " is letters, digits, '_', '-' and '.', not starting with '.' or '-', at " +
         "most 100 characters; got " + json(name).dump();
}

// Why a point attribute named in /output/attributes could never be written, or "": it must be a
// known attribute or one a node adds (NodeTypeInfo::adds_attributes).
std::string unknown_output_attribute(const Graph& g, const std::string& name) {
  if (find_known_attribute(name)) return "";
  for (const NodeDesc& d : g.nodes) {
    if (!d.info->adds_attributes) continue;
    ParamSet ps(d.info->params, d.params);
    ps.evaluate(ExprVars{});
    for (const std::string& a : d.info->adds_attributes(ps))
      if (a == name || a == "*") return "";
  }
  std::string known;
  for (const AttribDefault& a : known_point_attributes()) {
    if (!known.empty()) known += ", ";
    known += a.name;
  }
  return "unknown point attribute '" + name + "': no node adds it and it is none of " + known;
}

struct Loader {
  std::string file;

  [[noreturn]] void fail(const std::string& pointer, const std::string& msg) const {
    throw LoadError(file, pointer, msg);
  }

  ChannelSource channel(const ParamDecl& d, const json& j, const std::vector<std::string>& names,
                        const std::string& ptr) const {
    ChannelSource c;
    if (j.is_number()) {
      c.value = j.get<double>();
      if (d.type == ParamType::Int && c.value != std::floor(c.value))
        fail(ptr, "'" + d.name + "' is an integer, got " + j.dump());
      if (d.type == ParamType::Toggle && c.value != 0 && c.value != 1)
        fail(ptr, "'" + d.name + "' is a toggle: true, false, 0, 1 or an expression");
      // finite, within int or float, within the declared range: the same check as a value
      // from an expression or keys gets when it is evaluated (ParamSet::evaluate)
      if (const std::string bad = d.value_error(c.value); !bad.empty()) fail(ptr, bad);
      return c;
    }
    if (j.is_boolean()) {
      if (d.type != ParamType::Toggle)
        fail(ptr, "'" + d.name + "' is " + param_type_name(d.type) + ", got a boolean");
      c.value = j.get<bool>() ? 1 : 0;
      return c;
    }
    if (j.is_string()) {
      c.kind = ChannelSource::Kind::Expression;
      c.text = j.get<std::string>();
      try {
        Expression probe(c.text, names);
      } catch (const std::exception& e) {
        fail(ptr, "expression does not parse: " + std::string(e.what()));
      }
      return c;
    }
    if (j.is_object()) {
      c.kind = ChannelSource::Kind::Keys;
      for (auto it = j.begin(); it != j.end(); ++it)
        if (it.key() != "keys" && it.key() != "interp")
          fail(ptr + "/" + it.key(), "unknown keyframe field '" + it.key() + "'");
      if (!j.contains("keys") || !j["keys"].is_array() || j["keys"].empty())
        fail(ptr + "/keys", "keyframes need a non-empty 'keys' array of [seconds, value]");
      const json& keys = j["keys"];
      for (size_t k = 0; k < keys.size(); ++k) {
        const json& kv = keys[k];
        std::string kp = ptr + "/keys/" + std::to_string(k);
        if (!kv.is_array() || kv.size() != 2 || !kv[0].is_number() || !kv[1].is_number())
          fail(kp, "a key is [seconds, value], got " + kv.dump());
        double t = kv[0].get<double>();
        if (!c.keys.keys.empty() && !(t > c.keys.keys.back().first))
          fail(kp, "key times must increase strictly");
        c.keys.keys.push_back({t, kv[1].get<double>()});
      }
      std::string interp = "linear";
      if (j.contains("interp")) {
        if (!j["interp"].is_string()) fail(ptr + "/interp", "interp is \"linear\" or \"cubic\"");
        interp = j["interp"].get<std::string>();
      }
      if (interp != "linear" && interp != "cubic")
        fail(ptr + "/interp", "interp is \"linear\" or \"cubic\", got \"" + interp + "\"");
      c.keys.cubic = interp == "cubic";
      return c;
    }
    fail(ptr, "'" + d.name + "' is " + param_type_name(d.type) + ", got " + type_of(j));
  }

  ParamValue value(const ParamDecl& d, const json& j, const std::vector<std::string>& names,
                   const std::string& ptr) const {
    ParamValue v;
    switch (d.type) {
      case ParamType::Float:
      case ParamType::Int:
      case ParamType::Toggle:
        v.channels.push_back(channel(d, j, names, ptr));
        break;
      case ParamType::Vec3:
        if (!j.is_array() || j.size() != 3)
          fail(ptr, "'" + d.name + "' is a vector of 3 components, got " +
                        (j.is_array() ? std::to_string(j.size()) + " components" : type_of(j)));
        for (int k = 0; k < 3; ++k)
          v.channels.push_back(channel(d, j[k], names, ptr + "/" + std::to_string(k)));
        break;
      case ParamType::String:
        if (!j.is_string()) fail(ptr, "'" + d.name + "' is a string, got " + type_of(j));
        v.text = j.get<std::string>();
        break;
      case ParamType::Menu: {
        if (!j.is_string()) fail(ptr, "'" + d.name + "' is a string, got " + type_of(j));
        v.text = j.get<std::string>();
        bool ok = false;
        std::string choices;
        for (auto& m : d.menu) {
          ok = ok || m == v.text;
          choices += (choices.empty() ? "" : ", ") + ("\"" + m + "\"");
        }
        if (!ok) fail(ptr, "'" + d.name + "' must be one of " + choices + ", got \"" + v.text + "\"");
        break;
      }
      case ParamType::StringList:
        if (!j.is_array()) fail(ptr, "'" + d.name + "' is an array of strings, got " + type_of(j));
        for (size_t k = 0; k < j.size(); ++k) {
          if (!j[k].is_string())
            fail(ptr + "/" + std::to_string(k), "expected a string, got " + type_of(j[k]));
          v.list.push_back(j[k].get<std::string>());
        }
        break;
    }
    return v;
  }

  static void allow_keys(const Loader& l, const json& obj, const std::string& ptr,
                         std::initializer_list<const char*> keys) {
    for (auto it = obj.begin(); it != obj.end(); ++it) {
      bool ok = false;
      for (const char* k : keys) ok = ok || it.key() == k;
      if (!ok) l.fail(ptr + "/" + it.key(), "unknown field '" + it.key() + "'");
    }
  }

  Graph load(json root, const std::vector<Override>& overrides) {
    Graph g;
    g.file = file;
    g.base_dir = std::filesystem::path(file).parent_path().string();
    if (!root.is_object()) fail("", "the graph must be a JSON object");
    allow_keys(*this, root, "",
               {"$schema", "grains_graph", "name", "fps", "frames", "seed", "nodes", "output"});
    // "$schema": the JSON Schema an editor checks the file with (docs/graph.schema.json); the
    // loader does not read it
    if (root.contains("$schema") && !root["$schema"].is_string())
      fail("/$schema", "$schema is a string (the path or address of graph.schema.json)");
    if (!root.contains("grains_graph")) fail("/grains_graph", "missing: this file is not a grains graph");
    if (!root["grains_graph"].is_number_integer() || root["grains_graph"].get<int64_t>() != 1)
      fail("/grains_graph", "unsupported version " + root["grains_graph"].dump() + " (expected 1)");
    if (root.contains("name")) {
      if (!root["name"].is_string()) fail("/name", "name is a string");
      g.name = root["name"].get<std::string>();
      if (std::string bad = plain_name_problem("graph name", g.name); !bad.empty()) fail("/name", bad);
    } else {
      g.name = std::filesystem::path(file).stem().string();
    }
    if (root.contains("fps")) {
      if (!root["fps"].is_number()) fail("/fps", "fps is a number, got " + type_of(root["fps"]));
      g.fps = root["fps"].get<double>();
      if (!(g.fps >= kMinFps && g.fps <= kMaxFps))
        fail("/fps", "fps must lie between " + json(kMinFps).dump() + " and " + json(kMaxFps).dump() +
                         ", got " + root["fps"].dump());
    }
    if (root.contains("frames")) {
      if (!root["frames"].is_number_integer())
        fail("/frames", "frames is an integer, got " + root["frames"].dump());
      int64_t f = root["frames"].get<int64_t>();
      if (f <= 0) fail("/frames", "frames must be at least 1, got " + std::to_string(f));
      if (f > std::numeric_limits<int>::max())
        fail("/frames", "frames must be at most " +
                            std::to_string(std::numeric_limits<int>::max()) + ", got " +
                            std::to_string(f));
      g.frames = static_cast<int>(f);
    }
    if (root.contains("seed")) {
      const json& seed = root["seed"];
      if (!seed.is_number_unsigned() && !(seed.is_number_integer() && seed.get<int64_t>() >= 0))
        fail("/seed", "seed is an integer from 0 to 18446744073709551615");
      g.seed = root["seed"].get<uint64_t>();
    }
    if (!root.contains("nodes") || !root["nodes"].is_array())
      fail("/nodes", "the graph needs a 'nodes' array");
    json& nodes = root["nodes"];

    // overrides apply to the authored JSON, so they are validated like everything else
    for (const auto& o : overrides) {
      bool found = false;
      if (!o.type.empty()) found = true;
      for (auto& n : nodes)
        if (n.is_object() && (o.type.empty() ? n.contains("name") && n["name"] == o.node
                                             : n.contains("type") && n["type"] == o.type)) {
          json v;
          try {
            v = json::parse(o.value);
          } catch (const json::exception&) {
            v = o.value;
          }
          found = true;
          if (n.contains("params") && !n["params"].is_object()) continue;  // refused below
          n["params"][o.param] = v;
        }
      if (!found) throw LoadError("--set", "", "no node named '" + o.node + "' in " + file);
    }

    std::map<std::string, int> by_name;
    for (size_t k = 0; k < nodes.size(); ++k) {
      const json& n = nodes[k];
      std::string ptr = "/nodes/" + std::to_string(k);
      if (!n.is_object()) fail(ptr, "a node is an object, got " + type_of(n));
      allow_keys(*this, n, ptr, {"name", "type", "inputs", "params"});
      if (!n.contains("name") || !n["name"].is_string() || n["name"].get<std::string>().empty())
        fail(ptr + "/name", "every node needs a non-empty string name");
      NodeDesc d;
      d.name = n["name"].get<std::string>();
      d.pointer = ptr;
      if (std::string bad = plain_name_problem("node name", d.name); !bad.empty())
        fail(ptr + "/name", bad);
      if (by_name.count(d.name)) fail(ptr + "/name", "duplicate node name '" + d.name + "'");
      by_name[d.name] = static_cast<int>(k);
      if (!n.contains("type") || !n["type"].is_string()) fail(ptr + "/type", "every node needs a string type");
      d.type = n["type"].get<std::string>();
      d.info = find_node_type(d.type);
      if (!d.info) {
        std::string known;
        for (auto* t : node_types()) known += (known.empty() ? "" : ", ") + t->type;
        fail(ptr + "/type", "unknown node type '" + d.type + "' (known: " + known + ")");
      }
      std::vector<std::string> names;
      for (const auto& p : d.info->params)
        for (auto& c : p.channel_names()) names.push_back(c);
      if (n.contains("params")) {
        const json& params = n["params"];
        if (!params.is_object()) fail(ptr + "/params", "params is an object");
        for (auto it = params.begin(); it != params.end(); ++it) {
          std::string pp = ptr + "/params/" + it.key();
          const ParamDecl* decl = d.info->find_param(it.key());
          if (!decl)
            fail(pp, "unknown parameter '" + it.key() + "' for node type '" + d.type +
                         "' (see `grains nodes " + d.type + "`)");
          d.params[it.key()] = value(*decl, it.value(), names, pp);
        }
      }
      g.nodes.push_back(std::move(d));
    }

    // inputs: exist, are not colliders or solvers, and hold no cycle
    for (size_t k = 0; k < nodes.size(); ++k) {
      const json& n = nodes[k];
      NodeDesc& d = g.nodes[k];
      std::string ptr = d.pointer + "/inputs";
      if (!n.contains("inputs")) continue;
      if (!n["inputs"].is_array()) fail(ptr, "inputs is an array of node names");
      if (d.info->role == NodeRole::Collider && !n["inputs"].empty())
        fail(ptr, "a collider takes no inputs");
      for (size_t i = 0; i < n["inputs"].size(); ++i) {
        const json& in = n["inputs"][i];
        std::string ip = ptr + "/" + std::to_string(i);
        if (!in.is_string()) fail(ip, "an input is a node name, got " + type_of(in));
        auto it = by_name.find(in.get<std::string>());
        if (it == by_name.end()) fail(ip, "input '" + in.get<std::string>() + "' names no node");
        NodeRole r = g.nodes[it->second].info->role;
        if (r == NodeRole::Collider || r == NodeRole::Solver)
          fail(ip, "input '" + in.get<std::string>() + "' is a " +
                       (r == NodeRole::Collider ? "collider" : "solver") +
                       ": colliders are listed in a solver's 'colliders', solvers end chains");
        d.inputs.push_back(it->second);
      }
    }
    // depth-first, with an explicit stack: a chain may be as long as the file allows
    std::vector<int> state(g.nodes.size(), 0);  // 0 new, 1 on stack, 2 done
    std::vector<std::pair<int, size_t>> stack;   // node, next input to visit
    for (size_t root = 0; root < g.nodes.size(); ++root) {
      if (state[root] != 0) continue;
      state[root] = 1;
      stack.push_back({static_cast<int>(root), 0});
      while (!stack.empty()) {
        const int k = stack.back().first;
        const size_t i = stack.back().second++;
        if (i == g.nodes[k].inputs.size()) {
          state[k] = 2;
          stack.pop_back();
          continue;
        }
        const int in = g.nodes[k].inputs[i];
        if (state[in] == 1)
          fail(g.nodes[k].pointer + "/inputs/" + std::to_string(i),
               "cycle: '" + g.nodes[k].name + "' depends on itself through '" + g.nodes[in].name + "'");
        if (state[in] == 0) {
          state[in] = 1;
          stack.push_back({in, 0});
        }
      }
    }

    // solvers: colliders named exist; every chain node reaches a solver
    std::vector<char> reaches(g.nodes.size(), 0);
    auto mark = [&](int solver) {
      std::vector<int> todo = {solver};
      while (!todo.empty()) {
        const int k = todo.back();
        todo.pop_back();
        if (reaches[k]) continue;
        reaches[k] = 1;
        todo.insert(todo.end(), g.nodes[k].inputs.begin(), g.nodes[k].inputs.end());
      }
    };
    for (size_t k = 0; k < g.nodes.size(); ++k) {
      NodeDesc& d = g.nodes[k];
      if (d.info->role != NodeRole::Solver) continue;
      g.solvers.push_back(static_cast<int>(k));
      mark(static_cast<int>(k));
      auto it = d.params.find("colliders");
      if (it == d.params.end()) continue;
      for (size_t c = 0; c < it->second.list.size(); ++c) {
        const std::string& cn = it->second.list[c];
        int ci = g.find(cn);
        std::string cp = d.pointer + "/params/colliders/" + std::to_string(c);
        if (ci < 0) fail(cp, "collider '" + cn + "' names no node");
        if (g.nodes[ci].info->role != NodeRole::Collider)
          fail(cp, "'" + cn + "' is a " + g.nodes[ci].type + " node, not a collider");
      }
    }
    for (size_t k = 0; k < g.nodes.size(); ++k) {
      const NodeDesc& d = g.nodes[k];
      if (d.info->role == NodeRole::Collider || reaches[k]) continue;
      fail(d.pointer, "node '" + d.name + "' is in no chain that reaches a solver");
    }
    if (g.solvers.empty()) fail("/nodes", "the graph has no solver node");

    // node-specific checks (files exist, ...), with defaults filled in
    for (const auto& d : g.nodes) {
      if (!d.info->check) continue;
      ParamSet ps(d.info->params, d.params);
      try {
        ps.evaluate(ExprVars{});
      } catch (const ParamRangeError& e) {  // an expression's value at the start
        fail(d.pointer + "/params/" + e.param, e.what());
      }
      auto [msg, param] = d.info->check(ps, g.base_dir);
      if (!msg.empty()) fail(d.pointer + (param.empty() ? "" : "/params/" + param), msg);
    }

    if (root.contains("output")) {
      const json& o = root["output"];
      if (!o.is_object()) fail("/output", "output is an object");
      allow_keys(*this, o, "/output", {"dir", "every", "attributes", "formats"});
      if (o.contains("dir")) {
        if (!o["dir"].is_string() || o["dir"].get<std::string>().empty())
          fail("/output/dir", "dir is a non-empty string");
        g.output.dir = o["dir"].get<std::string>();
      }
      if (o.contains("every")) {
        if (!o["every"].is_number_integer() || o["every"].get<int64_t>() < 1)
          fail("/output/every", "every is an integer of at least 1");
        // within int: a larger one would wrap (4294967296 to 0, then f % every divides by 0)
        if (o["every"].get<int64_t>() > std::numeric_limits<int>::max())
          fail("/output/every", "every must be at most " +
                                    std::to_string(std::numeric_limits<int>::max()));
        g.output.every = o["every"].get<int>();
      }
      if (o.contains("attributes")) {
        if (!o["attributes"].is_array()) fail("/output/attributes", "attributes is an array of names");
        for (size_t k = 0; k < o["attributes"].size(); ++k) {
          const json& a = o["attributes"][k];
          if (!a.is_string() || a.get<std::string>().empty())
            fail("/output/attributes/" + std::to_string(k), "an attribute is a non-empty name");
          g.output.attributes.push_back(a.get<std::string>());
          if (std::string why = unknown_output_attribute(g, g.output.attributes.back()); !why.empty())
            fail("/output/attributes/" + std::to_string(k), why);
        }
      }
      if (o.contains("formats")) {
        const json& f = o["formats"];
        const std::vector<std::string>& known = output_format_names();
        std::string list;
        for (const std::string& k : known) list += (list.empty() ? "\"" : ", \"") + k + "\"";
        if (!f.is_array() || f.empty())
          fail("/output/formats",
               "formats is an array of frame formats, at least one, each one of " + list);
        g.output.formats.clear();
        for (size_t k = 0; k < f.size(); ++k) {
          const std::string at = "/output/formats/" + std::to_string(k);
          if (!f[k].is_string()) fail(at, "a format is a string, one of " + list);
          const std::string name = f[k].get<std::string>();
          if (std::find(known.begin(), known.end(), name) == known.end())
            fail(at, "unknown frame format '" + name + "': one of " + list);
          if (std::find(g.output.formats.begin(), g.output.formats.end(), name) !=
              g.output.formats.end())
            fail(at, "format '" + name + "' is named twice");
          g.output.formats.push_back(name);
        }
      }
    } else {
      g.output.dir = "out/" + g.name;
    }
    return g;
  }
};

}  // namespace

ParamValue parse_param_value(const ParamDecl& decl, const std::string& json_text,
                             const std::vector<std::string>& channel_names, const std::string& file,
                             const std::string& pointer) {
  json v;
  try {
    v = json::parse(json_text);
  } catch (const json::exception&) {
    v = json_text;
  }
  Loader l{file};
  return l.value(decl, v, channel_names, pointer);
}

Graph parse_graph(const std::string& text, const std::string& file,
                  const std::vector<Override>& overrides) {
  json root;
  try {
    root = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, or out_of_range for a number like 1e999
    throw LoadError(file, "", std::string("malformed JSON: ") + e.what());
  }
  Loader l{file};
  try {
    return l.load(std::move(root), overrides);
  } catch (const json::exception& e) {  // a shape the checks above missed: still bad input
    throw LoadError(file, "", std::string("unexpected JSON: ") + e.what());
  }
}

Graph load_graph(const std::string& path, const std::vector<Override>& overrides) {
  if (std::string bad = input_file_problem(path, kMaxGraphFileBytes); !bad.empty())
    throw LoadError(path, "", "the graph file " + bad);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw LoadError(path, "", "cannot open the graph file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_graph(ss.str(), path, overrides);
}

}  // namespace grains
