// The grains-lab program: the measurements behind BENCHMARKS.md and VALIDATION.md, apart from
// the product (`grains`, app/). It links the engine, the nodes and the image module
// (viewer-offline/image.h), never app/'s command line.
//   grains-lab bench     speed versus error over settings (lab/bench.h)
//   grains-lab features  the cost of each grains feature on one scene (lab/features.h)
//   grains-lab laws      published granular laws (lab/validation.h)
// Exit codes as `grains`: 0 success, 2 bad input, 1 failure while running.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "cli/log.h"
#include "cli/options.h"
#include "cli/program.h"
#include "engine/geometry_io.h"
#include "engine/graph.h"
#include "engine/node.h"
#include "lab/bench.h"
#include "lab/features.h"
#include "lab/validation.h"
#include "nodes/register.h"

namespace {

int lab_main(int argc, char** argv) {
  using namespace grains;
  register_builtin_nodes();
  CLI::App app{"grains-lab: benchmarks and validation of the grains solver (bench/README.md)"};
  app.require_subcommand(1);

  BenchOptions bench_opts;
  auto* bench = add_bench_command(app, bench_opts, argc, argv);
  FeatureOptions features_opts;
  auto* features = add_features_command(app, features_opts, argc, argv);
  ValidationOptions laws_opts;
  auto* laws = add_validation_command(app, laws_opts, argc, argv);
  bool quiet = false, verbose = false;
  for (CLI::App* command : {bench, features, laws}) add_verbosity_flags(command, quiet, verbose);

  if (const int rc = parse_command_line("grains-lab", app, argc, argv); rc >= 0) return rc;
  set_log_level(quiet, verbose);

  return report_errors("grains-lab", [&]() -> int {
    if (bench->parsed()) return run_bench(bench_opts);
    if (features->parsed()) return run_feature_bench(features_opts);
    if (laws->parsed()) return run_validation(laws_opts);
    return 0;
  });
}

}  // namespace

int main(int argc, char** argv) {
  return lab_main(argc, argv);
}
