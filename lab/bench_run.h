// What the two benchmarks of `grains-lab` share: the speed-versus-error sweep (lab/bench.h,
// `grains-lab bench`) and the feature-cost table (lab/features.h, `grains-lab features`) read a
// scene's sweep file, run a scene the same way — in a forked child, with `--set`-style
// overrides, timing only Simulation::step_frame — describe the machine and format numbers the
// same way, and keep each other's sections of the Markdown report. See bench/README.md.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "engine/graph.h"

namespace grains {

struct BenchSetting {
  int substeps = 1;
  int iterations = 1;
  bool operator==(const BenchSetting& o) const {
    return substeps == o.substeps && iterations == o.iterations;
  }
};

// A scene's sweep: from its sidecar NAME.sweep.json, or the default one.
struct BenchSweep {
  std::vector<BenchSetting> settings;
  BenchSetting reference;
  int frames = 0;  // 0: the graph's own
};

// One row of results.csv.
struct BenchRow {
  std::string scene;  // graph name
  std::string path;   // graph file
  BenchSetting setting;
  bool reference = false;
  int frames = 0;
  size_t points = 0;  // at the final frame
  int threads = 0;
  double wall_s = 0;               // the child's whole run: load, stepping, diagnostics
  double step_s = 0;               // stepping only (Simulation::step_frame), no I/O, no diagnostics
  double particle_iterations = 0;  // sum over substeps of points x iterations
  double constraint_iterations = 0;  // sum over substeps of constraints (at frame end) x iterations
  double peak_mib = 0;               // ru_maxrss of the child
  double bytes_per_grain = 0;        // (peak - resident before the simulation was built) / points
  double error_radii = 0;            // RMS final-position difference to the reference / mean pscale
  size_t compared = 0;               // ids present in both runs
  float max_penetration = 0, mean_penetration = 0;  // final frame (FrameStats)
  float max_strain = 0;                             // max over all frames
  double energy_initial = 0, energy_final = 0, energy_drift = 0;
  double s_per_frame() const { return frames > 0 ? step_s / frames : 0; }
  double pi_per_s() const { return step_s > 0 ? particle_iterations / step_s : 0; }
  double ci_per_s() const { return step_s > 0 ? constraint_iterations / step_s : 0; }
};

// The default sweep: (1,5) (1,10) (2,10) (2,20) (4,20), reference (8,40).
BenchSweep default_bench_sweep();
// Reads `graph.sweep.json` next to the graph when it exists, else the default sweep.
// Throws LoadError on a malformed sidecar.
BenchSweep load_bench_sweep(const std::string& graph_path);

// The Markdown report's features section starts and ends with these lines.
inline constexpr const char* kFeaturesBegin = "<!-- features:begin -->";
inline constexpr const char* kFeaturesEnd = "<!-- features:end -->";

// Hand-written notes in the report (what a sweep cannot measure, e.g. the contact-loop floor of
// bench/contact_bound.cpp) sit between these lines; `grains-lab bench` carries them over unchanged.
inline constexpr const char* kNotesBegin = "<!-- notes:begin -->";
inline constexpr const char* kNotesEnd = "<!-- notes:end -->";

// The section of `md` between the markers `begin` and `end` (markers included, with its final
// newline), or "" when `md` has none (or only one of the markers). The section ends at the first
// end marker and starts at the last begin marker before it.
std::string marked_section_of(const std::string& md, const char* begin, const char* end);
// Where that section is: [begin, end) of `md`, its end line's newline included; false when `md`
// has none. Ending at the first end marker and starting at the last begin marker before it, a
// stray begin marker never makes the section swallow the text that follows.
bool find_marked_section(const std::string& md, const char* begin_marker, const char* end_marker,
                         size_t& begin, size_t& end);
// The features section of a report: marked_section_of(md, kFeaturesBegin, kFeaturesEnd).
std::string features_section_of(const std::string& md);

}  // namespace grains

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
  bool dirty = false;  // built from sources that differed from the commit (lab/source.h)
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
