#include "engine/node.h"

#include <algorithm>
#include <map>

namespace grains {

static std::map<std::string, NodeTypeInfo>& registry() {
  static std::map<std::string, NodeTypeInfo> r;
  return r;
}

const ParamDecl* NodeTypeInfo::find_param(const std::string& name) const {
  for (const auto& p : params)
    if (p.name == name) return &p;
  return nullptr;
}

void register_node_type(NodeTypeInfo info) {
  std::string t = info.type;
  registry()[t] = std::move(info);
}

const NodeTypeInfo* find_node_type(const std::string& type) {
  auto it = registry().find(type);
  return it == registry().end() ? nullptr : &it->second;
}

std::vector<const NodeTypeInfo*> node_types() {
  std::vector<const NodeTypeInfo*> out;
  for (auto& [k, v] : registry()) out.push_back(&v);
  return out;
}

}  // namespace grains
