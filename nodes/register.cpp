#include "nodes/register.h"

namespace grains {
void register_builtin_nodes() {
  static bool done = false;
  if (done) return;
  done = true;
  register_source_node();
  register_group_node();
  register_force_node();
  register_merge_node();
  register_kill_node();
  register_attribute_node();
  register_collider_node();
  register_solver_node();
  register_grains_node();
  register_target_node();
}
}  // namespace grains
