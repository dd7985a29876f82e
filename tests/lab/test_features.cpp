// `grains-lab features` (lab/features.h, bench/README.md): features.csv has the
// baseline first, a row per feature with its --set overrides and finite positive figures, and the
// baseline again last; the report's features section is replaced between its markers and the rest
// of the report is kept, by this mode and by the sweep; bad invocations exit with code 2.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "lab/bench.h"
#include "lab/features.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;
namespace fs = std::filesystem;

namespace {

size_t count_of(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

std::string tiny_scene() {
  return source_dir() + "/tests/data/bench_tiny.json";
}

}  // namespace

TEST_CASE("features writes the baseline, every feature and the baseline again", "[bench][lab]") {
  std::string dir = temp_dir("bench_features");
  std::string md = write_file(dir, "B.md", "# Report\n\nkeep this line\n");
  // one thread: the test's timings should not depend on what else the machine is doing
  REQUIRE(
      run_lab("features " + tiny_scene() + " --frames 3 --threads 1 --out " + dir + " --md " + md,
              dir + "/log") == 0);

  std::vector<std::string> lines = split(read_text(dir + "/features.csv"), '\n');
  REQUIRE(!lines.empty());
  CHECK(lines[0] == features_csv_header());
  std::vector<std::string> header = split(lines[0], ',');
  auto col = [&](const std::string& name) {
    auto it = std::find(header.begin(), header.end(), name);
    REQUIRE(it != header.end());
    return static_cast<size_t>(it - header.begin());
  };
  const std::vector<BenchFeature>& features = bench_features();
  REQUIRE(lines.size() == 1 + features.size() + 2);

  for (size_t k = 1; k < lines.size(); ++k) {
    std::vector<std::string> f = split(lines[k], ',');
    REQUIRE(f.size() == header.size());
    // the baseline first, the features in table order, the baseline again last
    std::string want = k == 1                  ? kFeatureBaseline
                       : k + 1 == lines.size() ? kFeatureBaselineAgain
                                               : features[k - 2].name;
    INFO("row " << k << ": " << lines[k]);
    CHECK(f[col("feature")] == want);
    std::string sets;
    if (k >= 2 && k + 1 < lines.size())
      for (const auto& s : features[k - 2].sets) sets += (sets.empty() ? "" : " ") + s;
    CHECK(f[col("sets")] == sets);
    CHECK(f[col("scene")] == "bench_tiny");
    CHECK(std::stoi(f[col("frames")]) == 3);
    CHECK(std::stoi(f[col("points")]) == 216);
    CHECK(std::stoi(f[col("threads")]) == 1);
    CHECK(std::stoi(f[col("substeps")]) == 2);  // the scene as written
    CHECK(std::stoi(f[col("iterations")]) == 20);
    for (const char* c : {"step_s", "s_per_frame", "particle_iterations_per_s", "cost_ratio",
                          "peak_mib", "bytes_per_grain"}) {
      double v = std::stod(f[col(c)]);
      INFO(c);
      CHECK(std::isfinite(v));
      CHECK(v > 0);
    }
    double max_pen = std::stod(f[col("max_penetration")]);
    double mean_pen = std::stod(f[col("mean_penetration")]);
    double moved = std::stod(f[col("moved_radii")]);
    CHECK(std::isfinite(max_pen));
    CHECK(mean_pen >= 0);
    CHECK(max_pen >= mean_pen);
    CHECK(std::isfinite(moved));
    CHECK(moved >= 0);
    CHECK(std::stoi(f[col("compared")]) == 216);
    if (k == 1) {
      CHECK(std::stod(f[col("cost_ratio")]) == Approx(1.0).margin(1e-4));
      CHECK(moved == 0);
    }
    // the same simulation again: bit-for-bit the same final positions (determinism)
    if (k + 1 == lines.size()) CHECK(moved == 0);
  }

  std::string report = read_text(md);
  CHECK_THAT(report, Catch::StartsWith("# Report\n\nkeep this line\n"));
  CHECK(count_of(report, kFeaturesBegin) == 1);
  CHECK(count_of(report, kFeaturesEnd) == 1);
  CHECK_THAT(report, Catch::Contains("## Feature cost: bench_tiny"));
  CHECK_THAT(report, Catch::Contains("| feature | --set | s/frame | particle-iter/s | cost |"));
  CHECK_THAT(report, Catch::Contains("| baseline |  |"));
  CHECK_THAT(report, Catch::Contains("| mass_shock_local | `grains.enable_mass_shock_scaling=1` "
                                     "`grains.mass_shock_method=local` |"));
  CHECK_THAT(report, Catch::Contains("features " + tiny_scene()));
  for (auto& e : fs::directory_iterator(dir))
    CHECK(e.path().filename().string().rfind(".run_", 0) != 0);

  SECTION("the sweep regenerates the report around the notes and the features section") {
    const std::string notes =
        std::string(kNotesBegin) + "\n## Notes\n\nhand-written\n" + kNotesEnd + "\n";
    write_file(dir, "B.md", report + "\n" + notes);
    REQUIRE(
        run_lab("bench " + tiny_scene() + " --quick --threads 1 --out " + dir + "/sweep --md " + md,
                dir + "/log2") == 0);
    std::string swept = read_text(md);
    CHECK_THAT(swept, Catch::StartsWith("# Benchmarks"));
    CHECK_THAT(swept, Catch::Contains("## bench_tiny"));
    CHECK(features_section_of(swept) == features_section_of(report));
    CHECK(marked_section_of(swept, kNotesBegin, kNotesEnd) == notes);
    CHECK(swept.find(notes) < swept.find(kFeaturesBegin));
  }
  SECTION("--only runs those features between the baselines and replaces the section") {
    REQUIRE(run_lab("features " + tiny_scene() + " --only clumping,max_neighbors_16 " +
                        "--frames 2 --threads 1 --out " + dir + " --md " + md,
                    dir + "/log2") == 0);
    std::vector<std::string> again = split(read_text(dir + "/features.csv"), '\n');
    REQUIRE(again.size() == 5);
    CHECK(split(again[1], ',')[0] == kFeatureBaseline);
    CHECK(split(again[2], ',')[0] == "clumping");
    CHECK(split(again[3], ',')[0] == "max_neighbors_16");
    CHECK(split(again[4], ',')[0] == kFeatureBaselineAgain);
    std::string replaced = read_text(md);
    CHECK_THAT(replaced, Catch::StartsWith("# Report\n\nkeep this line\n"));
    CHECK(count_of(replaced, kFeaturesBegin) == 1);
    CHECK_THAT(replaced, Catch::Contains("--only clumping,max_neighbors_16"));
    CHECK_THAT(replaced, !Catch::Contains("| mass_shock_local |"));
  }
}

TEST_CASE("features refuses bad invocations with exit code 2", "[bench][lab]") {
  std::string dir = temp_dir("bench_features_bad");
  std::string md = dir + "/B.md";
  std::string args = " --frames 1 --threads 1 --out " + dir + "/o --md " + md;
  CHECK(run_lab("features " + tiny_scene() + " --only no_such_feature" + args, dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("unknown feature 'no_such_feature'"));
  CHECK(run_lab("features " + tiny_scene() + " " + tiny_scene() + args, dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("measures one scene"));
  CHECK(run_lab("bench " + tiny_scene() + " --only clumping" + args, dir + "/log") ==
        2);  // the sweep has no features
  CHECK(run_lab("features " + dir + "/missing.json" + args, dir + "/log") == 2);
  std::string graph =
      write_file(dir, "x.json", R"({"grains_graph": 1, "name": "x", "frames": 2, "nodes": [
    {"name": "src", "type": "source", "params": {"size": [0.1, 0.1, 0.1], "separation": 0.05}},
    {"name": "g", "type": "grains", "inputs": ["src"]},
    {"name": "solver", "type": "solver", "inputs": ["g"]}]})");
  CHECK(run_lab("features " + graph + args, dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("grains node named `grains`"));
  // particle-iterations are counted from constant substeps and iterations
  std::string animated =
      write_file(dir, "y.json", R"({"grains_graph": 1, "name": "y", "frames": 2, "nodes": [
    {"name": "src", "type": "source", "params": {"size": [0.1, 0.1, 0.1], "separation": 0.05}},
    {"name": "grains", "type": "grains", "inputs": ["src"], "params": {"constraint_iterations": "5 + $SF"}},
    {"name": "solver", "type": "solver", "inputs": ["grains"]}]})");
  CHECK(run_lab("features " + animated + args, dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("constant `constraint_iterations`"));
  CHECK_FALSE(fs::exists(md));
  CHECK_FALSE(fs::exists(dir + "/o/features.csv"));
}

TEST_CASE("features section is replaced between its markers only", "[bench][lab]") {
  std::string section = std::string(kFeaturesBegin) + "\nnew\n" + kFeaturesEnd + "\n";
  CHECK(splice_features_section("", section) == section);
  CHECK(splice_features_section("# R\n\ntext\n\n\n", section) == "# R\n\ntext\n\n" + section);
  std::string old =
      std::string("# R\n\n") + kFeaturesBegin + "\nold\n" + kFeaturesEnd + "\n\n## after\n";
  CHECK(splice_features_section(old, section) == "# R\n\n" + section + "\n## after\n");
  CHECK(features_section_of(old) == std::string(kFeaturesBegin) + "\nold\n" + kFeaturesEnd + "\n");
  CHECK(features_section_of("# R\n").empty());
  // a begin marker without an end is text, not a section: nothing after it is swallowed
  std::string stray = std::string("# R\n") + kFeaturesBegin + "\nkeep\n";
  CHECK(features_section_of(stray).empty());
  std::string once = splice_features_section(stray, section);
  CHECK_THAT(once, Catch::StartsWith(stray));
  CHECK(splice_features_section(once, section) == once);
}
