#pragma once

namespace grains {
// Registers every built-in node type with the engine's registry; safe to call more than once.
void register_builtin_nodes();
}  // namespace grains
