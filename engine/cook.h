// Cooking one node in isolation (DESIGN §5): the node type runs on known points, with an
// optional ground plane, for a few substeps — the same evaluator as `grains run`, with a graph of
// that one node feeding a solver.
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "engine/particles.h"
#include "engine/simulation.h"

namespace grains {

struct CookOptions {
  int substeps = 1;
  bool error_control = false;  // off: exactly `substeps` substeps a frame, like a fixed solver
  int frames = 1;
  double fps = 24;
  bool ground = false;  // add a ground plane collider at ground_y
  float ground_y = 0;
  int threads = 0;
  uint64_t seed = 0;
  std::string out_dir;  // when set, frames and stats.csv are written there like `run`
  std::string source = "<cook>";  // names the input in errors
};

// Runs node type `type` with parameters NAME=VALUE (VALUE as JSON, or a bare string) on `state`
// for opt.frames frames of opt.substeps substeps; `state` holds the result. Bad input throws
// LoadError (unknown type, a type that does not act on particles, unknown parameter, bad value).
void cook_node(const std::string& type,
               const std::vector<std::pair<std::string, std::string>>& params,
               ParticleStore& state, const CookOptions& opt = {});
// The same with substeps given directly.
inline void cook_node(const std::string& type,
                      const std::vector<std::pair<std::string, std::string>>& params,
                      ParticleStore& state, int substeps) {
  CookOptions o;
  o.substeps = substeps;
  cook_node(type, params, state, o);
}

}  // namespace grains
