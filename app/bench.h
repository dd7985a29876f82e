// `grains bench`: speed versus error (DESIGN §5, §7). Runs each benchmark scene at several
// (substeps, constraint_iterations) settings, each in its own forked child process, and compares
// every run's final positions with a converged reference run of the same scene. Writes
// DIR/results.csv, DIR/pareto.png and a Markdown report (BENCHMARKS.md). See bench/README.md.
#pragma once
#include <string>
#include <vector>

namespace CLI {
class App;
}

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

// The default sweep: (1,5) (1,10) (2,10) (2,20) (4,20), reference (8,40).
BenchSweep default_bench_sweep();
// Reads `graph.sweep.json` next to the graph when it exists, else the default sweep.
// Throws LoadError on a malformed sidecar.
BenchSweep load_bench_sweep(const std::string& graph_path);
// The --quick version: the first two settings, the reference at half its substeps and
// iterations (at least 1 each, and never below a kept setting's), at most 12 frames.
BenchSweep quick_bench_sweep(const BenchSweep& s);

struct BenchOptions {
  std::vector<std::string> scenes;  // empty: every bench/*.json (not *.sweep.json), sorted
  std::string out_dir = "out/bench";
  std::string md_path = "BENCHMARKS.md";
  bool quick = false;
  int frames = 0;   // > 0 overrides every scene's frame count
  int threads = 0;  // <= 0: every core
  // --repeat: each setting runs this many times, in rounds over all settings; its timings are
  // the fastest run's (the results are bit-identical, so only timings differ)
  int repeat = 1;
  std::string command;  // the command line, for the report
  // --features: the feature-cost table (app/bench_features.h) instead of the sweep
  bool features = false;
  std::vector<std::string> only;  // --only: those features (empty: all)
};

// One row of results.csv.
struct BenchRow {
  std::string scene;  // graph name
  std::string path;   // graph file
  BenchSetting setting;
  bool reference = false;
  int frames = 0;
  size_t points = 0;       // at the final frame
  int threads = 0;
  double wall_s = 0;       // the child's whole run: load, stepping, diagnostics
  double step_s = 0;       // stepping only (Simulation::step_frame), no I/O, no diagnostics
  double particle_iterations = 0;  // sum over substeps of points x iterations
  double constraint_iterations = 0;  // sum over substeps of constraints (at frame end) x iterations
  double peak_mib = 0;     // ru_maxrss of the child
  double bytes_per_grain = 0;  // (peak - resident before the simulation was built) / points
  double error_radii = 0;  // RMS final-position difference to the reference / mean pscale
  size_t compared = 0;     // ids present in both runs
  float max_penetration = 0, mean_penetration = 0;  // final frame (FrameStats)
  float max_strain = 0;    // max over all frames
  double energy_initial = 0, energy_final = 0, energy_drift = 0;
  double s_per_frame() const { return frames > 0 ? step_s / frames : 0; }
  double pi_per_s() const { return step_s > 0 ? particle_iterations / step_s : 0; }
  double ci_per_s() const { return step_s > 0 ? constraint_iterations / step_s : 0; }
};

// The documented header of results.csv.
const char* bench_csv_header();

// Runs the benchmark (the feature-cost table with options.features); returns the process exit code (0 ok, 2 bad input, 1 a run failed).
// Throws LoadError for a bad scene or sidecar (before any run starts).
int run_bench(const BenchOptions& options);

// Adds the `bench` subcommand to the program's parser, filling `options`; records argv as the
// command to reproduce.
CLI::App* add_bench_command(CLI::App& app, BenchOptions& options, int argc, char** argv);

}  // namespace grains
