// merge: combines chains. Its inputs run left to right; nodes below it act on the union of
// their streams. It has nothing of its own to cook.
#include "engine/node.h"
#include "nodes/register.h"

namespace grains {

void register_merge_node() {
  NodeTypeInfo t;
  t.type = "merge";
  t.doc = "Combines chains: its inputs run left to right; nodes below act on all their streams.";
  t.role = NodeRole::Merge;
  register_node_type(std::move(t));
}

}  // namespace grains
