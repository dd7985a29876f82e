#include "nodes/register.h"

namespace grains {
void register_builtin_nodes() {}
}  // namespace grains
