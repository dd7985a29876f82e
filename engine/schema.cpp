#include "engine/schema.h"

#include <limits>
#include <nlohmann/json.hpp>

#include "engine/graph.h"
#include "engine/node.h"

namespace grains {

namespace {

using json = nlohmann::ordered_json;

// the bounds ParamDecl::value_error puts on every literal
constexpr double kFloatMax = 3.4028234663852886e38;
constexpr double kIntMax = 2147483647.0;

// a node or graph name: what plain_name_problem (graph.cpp) allows
const char* const kPlainName = "^[A-Za-z0-9_][A-Za-z0-9_.-]{0,99}$";

json number_literal(const ParamDecl& d) {
  const bool integer = d.type == ParamType::Int;
  json s{{"type", integer ? "integer" : "number"}};
  const double limit = integer ? kIntMax : kFloatMax;
  if (d.has_min && d.min_exclusive) s["exclusiveMinimum"] = d.min;
  else s["minimum"] = d.has_min ? std::max(d.min, -limit) : -limit;
  s["maximum"] = d.has_max ? std::min(d.max, limit) : limit;
  return s;
}

// one numeric channel: a literal, an expression evaluated every substep, or keyframes
json channel(const ParamDecl& d) {
  json literal = d.type == ParamType::Toggle ? json{{"type", "boolean"}} : number_literal(d);
  json any = json::array({literal});
  if (d.type == ParamType::Toggle) any.push_back({{"enum", {0, 1}}});
  any.push_back({{"type", "string"}, {"description", "an expression, evaluated every substep"}});
  any.push_back({{"$ref", "#/definitions/keyframes"}});
  return {{"anyOf", any}};
}

json param_schema(const ParamDecl& d) {
  json s;
  switch (d.type) {
    case ParamType::Float:
    case ParamType::Int:
    case ParamType::Toggle:
      s = channel(d);
      break;
    case ParamType::Vec3:
      s = {{"type", "array"}, {"items", channel(d)}, {"minItems", 3}, {"maxItems", 3}};
      break;
    case ParamType::String:
      s = {{"type", "string"}};
      break;
    case ParamType::Menu:
      s = {{"enum", d.menu}};
      break;
    case ParamType::StringList:
      s = {{"type", "array"}, {"items", {{"type", "string"}}}};
      break;
  }
  std::string text = d.doc;
  if (!d.units.empty()) text += " (" + d.units + ")";
  if (!d.scale_attribute.empty()) text += "; scaled by the point attribute " + d.scale_attribute;
  s["description"] = text;
  switch (d.type) {
    case ParamType::Float: s["default"] = d.def[0]; break;
    case ParamType::Int: s["default"] = static_cast<int>(d.def[0]); break;
    case ParamType::Toggle: s["default"] = d.def[0] != 0; break;
    case ParamType::Vec3: s["default"] = {d.def[0], d.def[1], d.def[2]}; break;
    case ParamType::String:
    case ParamType::Menu: s["default"] = d.def_string; break;
    case ParamType::StringList: s["default"] = json::array(); break;
  }
  return s;
}

json keyframes() {
  json key{{"type", "array"},
           {"description", "[seconds, value]; times increase strictly"},
           {"items", {{"type", "number"}}},
           {"minItems", 2},
           {"maxItems", 2}};
  return {{"type", "object"},
          {"description", "keyframes over seconds"},
          {"properties",
           {{"keys", {{"type", "array"}, {"items", key}, {"minItems", 1}}},
            {"interp", {{"enum", {"linear", "cubic"}}, {"default", "linear"}}}}},
          {"required", {"keys"}},
          {"additionalProperties", false}};
}

json node_schema(const std::vector<const NodeTypeInfo*>& types) {
  json names = json::array();
  for (const NodeTypeInfo* t : types) names.push_back(t->type);
  json node{
      {"type", "object"},
      {"properties",
       {{"name", {{"type", "string"}, {"pattern", kPlainName}, {"description", "unique in the graph"}}},
        {"type", {{"enum", names}}},
        {"inputs",
         {{"type", "array"},
          {"items", {{"type", "string"}}},
          {"description", "the nodes that run before this one, left to right"}}},
        {"params", {{"type", "object"}}}}},
      {"required", {"name", "type"}},
      {"additionalProperties", false}};
  json each = json::array();
  for (const NodeTypeInfo* t : types) {
    json then{{"properties", {{"params", {{"$ref", "#/definitions/params_" + t->type}}}}}};
    if (t->role == NodeRole::Collider) then["properties"]["inputs"] = {{"maxItems", 0}};
    each.push_back({{"if", {{"properties", {{"type", {{"const", t->type}}}}}, {"required", {"type"}}}},
                    {"then", then}});
  }
  node["allOf"] = each;
  return node;
}

json params_schema(const NodeTypeInfo& t) {
  json props = json::object();
  for (const ParamDecl& d : t.params) props[d.name] = param_schema(d);
  return {{"type", "object"},
          {"description", t.type + ": " + t.doc},
          {"properties", props},
          {"additionalProperties", false}};
}

}  // namespace

std::string graph_schema_text() {
  const std::vector<const NodeTypeInfo*> types = node_types();
  json output{
      {"type", "object"},
      {"properties",
       {{"dir", {{"type", "string"}, {"minLength", 1}, {"description", "output folder"}}},
        {"every",
         {{"type", "integer"},
          {"minimum", 1},
          {"maximum", std::numeric_limits<int>::max()},
          {"default", 1},
          {"description", "write every N-th frame"}}},
        {"attributes",
         {{"type", "array"},
          {"items", {{"type", "string"}, {"minLength", 1}}},
          {"description", "point attributes written besides P"}}},
        {"formats",
         {{"type", "array"},
          {"items", {{"enum", output_format_names()}}},
          {"minItems", 1},
          {"uniqueItems", true},
          {"default", json::array({"ply"})},
          {"description", "files each written frame is made as: ply (frame_NNNN.ply), vtp (VTK XML "
                          "PolyData frame_NNNN.vtp, listed with its time in frames.pvd)"}}}}},
      {"additionalProperties", false}};
  json definitions = json::object();
  definitions["keyframes"] = keyframes();
  definitions["node"] = node_schema(types);
  for (const NodeTypeInfo* t : types) definitions["params_" + t->type] = params_schema(*t);
  json schema{
      {"$schema", "http://json-schema.org/draft-07/schema#"},
      {"title", "Grains graph"},
      {"description", "A Grains node graph (generated by `grains schema` from the node types' "
                      "parameter tables)"},
      {"type", "object"},
      {"properties",
       {{"$schema", {{"type", "string"}, {"description", "this schema, for editors"}}},
        {"grains_graph", {{"const", 1}, {"description", "the format's version"}}},
        {"name", {{"type", "string"}, {"pattern", kPlainName}}},
        {"fps", {{"type", "number"}, {"minimum", kMinFps}, {"maximum", kMaxFps}, {"default", 24}}},
        {"frames",
         {{"type", "integer"}, {"minimum", 1}, {"maximum", std::numeric_limits<int>::max()}, {"default", 1}}},
        {"seed",
         {{"type", "integer"}, {"minimum", 0}, {"maximum", std::numeric_limits<uint64_t>::max()}, {"default", 0}}},
        {"nodes", {{"type", "array"}, {"items", {{"$ref", "#/definitions/node"}}}}},
        {"output", output}}},
      {"required", {"grains_graph", "nodes"}},
      {"additionalProperties", false},
      {"definitions", definitions}};
  return schema.dump(2) + "\n";
}

}  // namespace grains
