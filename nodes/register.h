#pragma once

namespace grains {
// Registers every built-in node type with the engine's registry; safe to call more than once.
void register_builtin_nodes();

// One per node file.
void register_source_node();
void register_group_node();
void register_force_node();
void register_merge_node();
void register_kill_node();
void register_attribute_node();
void register_collider_node();
void register_solver_node();
void register_grains_node();
void register_target_node();
}  // namespace grains
