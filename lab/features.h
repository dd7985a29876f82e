// `grains-lab features`: what each grains-node feature costs when it is on (the grains node
// must model only what a scene needs: a feature that is off costs nothing per iteration, and the
// benchmark shows what each one costs when on). One scene runs as written (the baseline), then
// once per feature with that feature's `--set` overrides, then as written again (how much timings
// wander); every run goes through the sweep's child runner (lab/bench_run.h), so s/frame,
// particle-iterations per second and peak memory mean what they mean in results.csv, and the
// final penetration sits beside them. Writes DIR/features.csv and replaces the section between
// the features markers of the Markdown report, leaving the rest of it alone. See bench/README.md.
#pragma once
#include <string>
#include <vector>

#include "lab/bench_run.h"

namespace CLI {
class App;
}

namespace grains {

// One row of the table besides the baselines.
struct BenchFeature {
  std::string name;               // `feature` in features.csv; what --only takes
  std::vector<std::string> sets;  // NODE.PARAM=VALUE, applied exactly like `grains run --set`
};

// Every feature the table measures, in report order (the baselines are not in it).
const std::vector<BenchFeature>& bench_features();

// features.csv's first and last rows: the scene as written, before and after the features.
inline constexpr const char* kFeatureBaseline = "baseline";
inline constexpr const char* kFeatureBaselineAgain = "baseline_again";

// The scene measured when none is given.
inline constexpr const char* kFeaturesDefaultScene = "bench/settle_100k.json";

// The documented header of features.csv.
const char* features_csv_header();

// `md` with its features section replaced by `section` (which carries its own markers), or with
// `section` appended after a blank line when `md` has none.
std::string splice_features_section(const std::string& md, const std::string& section);

struct FeatureOptions {
  std::vector<std::string> scenes;  // at most one; empty: kFeaturesDefaultScene
  std::vector<std::string> only;    // --only: those features (empty: all)
  std::string out_dir = "out/bench";
  std::string md_path = "BENCHMARKS.md";
  bool quick = false;   // at most 12 frames
  int frames = 0;       // > 0: every run's frame count (default: the sweep file's or the graph's)
  int threads = 0;      // <= 0: every core
  int repeat = 1;       // each row runs this many times, in rounds; its timings are the fastest
  std::string command;  // the command line, for the report
};

// Runs the feature-cost table. Returns the exit code (0 ok, 1 a run failed, 2 bad input).
// Throws LoadError for a bad scene, feature name or override, before any run starts.
int run_feature_bench(const FeatureOptions& options);

// Adds the `features` subcommand to the lab's parser, filling `options`; records argv as the
// command to reproduce.
CLI::App* add_features_command(CLI::App& app, FeatureOptions& options, int argc, char** argv);

}  // namespace grains
