// `grains-lab bench`: speed versus error (DESIGN §5, §7). Runs each benchmark scene at several
// (substeps, constraint_iterations) settings, each in its own forked child process, and compares
// every run's final positions with a converged reference run of the same scene. Writes
// DIR/results.csv, DIR/pareto.png and a Markdown report (BENCHMARKS.md). See bench/README.md.
#pragma once
#include <string>
#include <vector>

#include "lab/bench_run.h"

namespace CLI {
class App;
}

namespace grains {

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
};

// The documented header of results.csv.
const char* bench_csv_header();

// Runs the benchmark; returns the process exit code (0 ok, 2 bad input, 1 a run failed).
// Throws LoadError for a bad scene or sidecar (before any run starts).
int run_bench(const BenchOptions& options);

// Adds the `bench` subcommand to the lab's parser, filling `options`; records argv as the
// command to reproduce.
CLI::App* add_bench_command(CLI::App& app, BenchOptions& options, int argc, char** argv);

}  // namespace grains
