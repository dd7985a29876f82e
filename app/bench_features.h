// `grains bench --features`: what each grains-node feature costs when it is on (the grains node
// must model only what a scene needs: a feature that is off costs nothing per iteration, and the
// benchmark shows what each one costs when on). One scene runs as written (the baseline), then
// once per feature with that feature's `--set` overrides, then as written again (how much timings
// wander); every run goes through the sweep's child runner (app/bench_run.h), so s/frame,
// particle-iterations per second and peak memory mean what they mean in results.csv, and the
// final penetration sits beside them. Writes DIR/features.csv and replaces the section between
// the features markers of the Markdown report, leaving the rest of it alone. See bench/README.md.
#pragma once
#include <string>
#include <vector>

#include "app/bench.h"

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

// The Markdown report's features section starts and ends with these lines.
inline constexpr const char* kFeaturesBegin = "<!-- features:begin -->";
inline constexpr const char* kFeaturesEnd = "<!-- features:end -->";

// Hand-written notes in the report (what a sweep cannot measure, e.g. the contact-loop floor of
// bench/contact_bound.cpp) sit between these lines; `grains bench` carries them over unchanged.
inline constexpr const char* kNotesBegin = "<!-- notes:begin -->";
inline constexpr const char* kNotesEnd = "<!-- notes:end -->";

// The section of `md` between the markers `begin` and `end` (markers included, with its final
// newline), or "" when `md` has none (or only one of the markers). The section ends at the first
// end marker and starts at the last begin marker before it.
std::string marked_section_of(const std::string& md, const char* begin, const char* end);
// The features section of a report: marked_section_of(md, kFeaturesBegin, kFeaturesEnd).
std::string features_section_of(const std::string& md);
// `md` with its features section replaced by `section` (which carries its own markers), or with
// `section` appended after a blank line when `md` has none.
std::string splice_features_section(const std::string& md, const std::string& section);

// Runs the feature-cost table for `options.scenes` (at most one; default kFeaturesDefaultScene),
// `options.only` (feature names; empty: all), `options.frames`, `options.quick`,
// `options.threads`. Returns the exit code (0 ok, 1 a run failed, 2 bad input). Throws
// LoadError for a bad scene, feature name or override, before any run starts.
int run_feature_bench(const BenchOptions& options);

}  // namespace grains
