// The grains node (grains_node.cpp): registered with the others (nodes/register.h); this header
// is for the tests and tools that look into a running graph.
#pragma once

#include "engine/node.h"
#include "nodes/grains/solver.h"

namespace grains {

// The solver of a grains node, or null when `node` is not one.
const GrainsSolver* grains_solver(const Node& node);

}  // namespace grains
