// What the two modes of `grains bench` share: the speed-versus-error sweep (app/bench.cpp) and the
// feature-cost table (app/bench_features.cpp) run a scene the same way — in a forked child, with
// `--set`-style overrides, timing only Simulation::step_frame — and describe the machine and
// format numbers the same way in their reports. Internal to app/; see bench/README.md.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "app/bench.h"
#include "engine/graph.h"

namespace grains::bench {

// A final position keyed by (object index << 32 | id), so runs of one scene can be compared.
struct KeyedPos {
  int64_t key;
  float x, y, z;
};

// Refuses (LoadError) a scene without a solver node named `solver` and a grains node named
// `grains` (the bench scene convention, bench/README.md).
void check_bench_scene(const Graph& g, const std::string& path);

// The substeps of the node named `solver` and the constraint_iterations of the node named
// `grains`, as the graph sets them (their declared defaults when absent). Particle-iterations are
// counted from these, so an animated value is refused: throws LoadError.
BenchSetting scene_setting(const Graph& g);

// Runs the scene at `path` with `overrides` (applied exactly like `grains run --set`) for `frames`
// frames (<= 0: the graph's own) on `threads` threads, in a forked child so that its peak memory is
// its own; `label` names the run in messages. Returns the child's exit code (0, 2 for bad input,
// 1 for a failure). On 0 it fills every figure of `row` but scene, path, reference, error_radii
// and compared (`row.setting` is the run's substeps and constraint_iterations), the final
// `positions` sorted by key, and the final `mean_pscale`.
int run_child(const std::string& path, const std::vector<Override>& overrides,
              const std::string& label, int frames, int threads, const std::string& tmp_dir,
              BenchRow& row, std::vector<KeyedPos>& positions, double& mean_pscale);

// RMS distance over the keys present in both (sorted) sets; `compared` is how many. nan if none.
double rms_difference(const std::vector<KeyedPos>& a, const std::vector<KeyedPos>& b,
                      size_t& compared);

// The machine a report was measured on.
struct Machine {
  std::string cpu = "unknown processor";
  long cores = 1;
  double mem_gib = 0;
  std::string date;
  std::string commit;
  bool dirty = false;  // the working tree's engine/, nodes/ or app/ differ from the commit
  std::string load;    // /proc/loadavg's 1-minute figure when the benchmark started
};
Machine describe_machine();
// The report's Date, Machine and Source bullet lines.
std::string machine_markdown(const Machine& m, int threads);

// printf-formats `v` with `f`, "nan" when not finite.
std::string fmt(const char* f, double v);
// 1.23e7 -> "12.3 M".
std::string si(double v);
// `a` quoted for a POSIX shell where needed.
std::string quote_arg(const std::string& a);

}  // namespace grains::bench
