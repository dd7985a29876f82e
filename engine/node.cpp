#include "engine/node.h"

#include <algorithm>
#include <cstdio>
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

void check_point_budget(const std::string& node, double adding, size_t have, size_t max,
                        const std::string& what) {
  const double total = double(have) + adding;
  if (total <= double(max)) return;
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "node '%s': %s would bring the points to %.4g, more than the budget of %zu (about "
                "%.3g GB at %zu B a point); raise it with --max-points",
                node.c_str(), what.c_str(), total, max, total * double(kBytesPerPoint) / 1e9,
                kBytesPerPoint);
  throw BudgetError(buf);
}

std::vector<const NodeTypeInfo*> node_types() {
  std::vector<const NodeTypeInfo*> out;
  for (auto& [k, v] : registry()) out.push_back(&v);
  return out;
}

}  // namespace grains
