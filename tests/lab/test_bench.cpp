// `grains-lab bench` (DESIGN §5, §7): results.csv with its documented header and a row per setting,
// the reference's own error 0, pareto.png and the Markdown report.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "lab/bench.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;
namespace fs = std::filesystem;

TEST_CASE("bench --quick writes results.csv, pareto.png and the Markdown table", "[bench][lab]") {
  std::string dir = temp_dir("bench_quick");
  std::string scene = source_dir() + "/tests/data/bench_tiny.json";
  std::string md = dir + "/B.md";
  REQUIRE(run_lab("bench " + scene + " --quick --out " + dir + " --md " + md, dir + "/log") == 0);

  std::vector<std::string> lines = split(read_text(dir + "/results.csv"), '\n');
  REQUIRE(lines.size() >= 2);
  CHECK(lines[0] == bench_csv_header());
  std::vector<std::string> header = split(lines[0], ',');
  auto col = [&](const std::string& name) {
    auto it = std::find(header.begin(), header.end(), name);
    REQUIRE(it != header.end());
    return static_cast<size_t>(it - header.begin());
  };
  // the quick sweep: the sidecar's first two settings and the halved reference (2 x 10), which is
  // not among them, so three rows
  BenchSweep quick = quick_bench_sweep(load_bench_sweep(scene));
  REQUIRE(quick.settings.size() == 2);
  REQUIRE(lines.size() == 4);

  double cheapest = -1, ref_error = -1;
  int references = 0;
  for (size_t k = 1; k < lines.size(); ++k) {
    std::vector<std::string> f = split(lines[k], ',');
    REQUIRE(f.size() == header.size());
    CHECK(f[col("scene")] == "bench_tiny");
    CHECK(std::stoi(f[col("points")]) == 216);
    CHECK(std::stoi(f[col("frames")]) <= 12);
    double err = std::stod(f[col("error_radii")]);
    CHECK(std::isfinite(err));
    CHECK(err >= 0);
    CHECK(std::stod(f[col("particle_iterations_per_s")]) > 0);
    CHECK(std::stod(f[col("s_per_frame")]) > 0);
    CHECK(std::stod(f[col("peak_mib")]) > 0);
    CHECK(std::stoi(f[col("compared")]) == 216);
    CHECK(std::isfinite(std::stod(f[col("energy_drift")])));
    CHECK(std::stod(f[col("max_penetration")]) >= std::stod(f[col("mean_penetration")]));
    if (k == 1) cheapest = err;
    if (f[col("reference")] == "1") {
      ++references;
      ref_error = err;
      CHECK(std::stoi(f[col("substeps")]) == quick.reference.substeps);
      CHECK(std::stoi(f[col("iterations")]) == quick.reference.iterations);
    }
  }
  CHECK(references == 1);
  CHECK(ref_error == Approx(0).margin(1e-9));
  CHECK(cheapest >= ref_error);

  CHECK(fs::file_size(dir + "/pareto.png") > 1000);
  std::string report = read_text(md);
  CHECK_THAT(report, Catch::Contains("## bench_tiny"));
  CHECK_THAT(report, Catch::Contains("| substeps x iterations | s/frame | particle-iter/s |"));
  CHECK_THAT(report, Catch::Contains("| 2 x 10 **ref** |"));
  CHECK_THAT(report, Catch::Contains("bench " + scene + " --quick"));
  CHECK_THAT(report, Catch::Contains("cores"));
  // no temporary result files left behind
  for (auto& e : fs::directory_iterator(dir))
    CHECK(e.path().filename().string().rfind(".run_", 0) != 0);
}

TEST_CASE("bench sweep files: defaults, sidecars and errors", "[bench][lab]") {
  std::string dir = temp_dir("bench_sweep");
  BenchSweep d = load_bench_sweep(dir + "/nothing.json");
  CHECK(d.settings.size() == 5);
  CHECK(d.reference == BenchSetting{8, 40});
  write_file(dir, "a.sweep.json", R"({"settings": [[2, 20]], "reference": [4, 20], "frames": 3})");
  BenchSweep a = load_bench_sweep(dir + "/a.json");
  REQUIRE(a.settings.size() == 1);
  CHECK(a.settings[0] == BenchSetting{2, 20});
  CHECK(a.frames == 3);
  write_file(dir, "b.sweep.json", R"({"settings": [[2, 0]]})");
  CHECK_THROWS_AS(load_bench_sweep(dir + "/b.json"), LoadError);
  write_file(dir, "c.sweep.json", R"({"setings": [[2, 2]]})");
  CHECK_THROWS_AS(load_bench_sweep(dir + "/c.json"), LoadError);
  BenchSweep q = quick_bench_sweep(d);
  CHECK(q.settings.size() == 2);
  CHECK(q.reference == BenchSetting{4, 20});
}

TEST_CASE("bench refuses a scene without the solver and grains names", "[bench][lab]") {
  std::string dir = temp_dir("bench_bad");
  std::string graph =
      write_file(dir, "x.json", R"({"grains_graph": 1, "name": "x", "frames": 2, "nodes": [
    {"name": "src", "type": "source", "params": {"size": [0.1, 0.1, 0.1], "separation": 0.05}},
    {"name": "g", "type": "grains", "inputs": ["src"]},
    {"name": "s", "type": "solver", "inputs": ["g"]}]})");
  CHECK(run_lab("bench " + graph + " --out " + dir + "/o --md " + dir + "/B.md", dir + "/log") ==
        2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("solver node named `solver`"));
  CHECK_FALSE(fs::exists(dir + "/B.md"));
}

TEST_CASE("bench --repeat runs every setting again and keeps the fastest timings", "[bench][lab]") {
  std::string dir = temp_dir("bench_repeat");
  std::string scene = source_dir() + "/tests/data/bench_tiny.json";
  std::string md = dir + "/B.md";
  REQUIRE(run_lab("bench " + scene + " --quick --repeat 2 --threads 1 --out " + dir + " --md " + md,
                  dir + "/log") == 0);
  std::string log = read_text(dir + "/log");
  // the quick sweep's three settings, each once more in a second round
  size_t repeats = 0;
  for (size_t at = log.find("run 2:"); at != std::string::npos; at = log.find("run 2:", at + 1))
    ++repeats;
  CHECK(repeats == 3);
  // the runs are bit-identical, so a repeat only changes timings
  CHECK_THAT(log, !Catch::Contains("not deterministic"));
  std::vector<std::string> lines = split(read_text(dir + "/results.csv"), '\n');
  CHECK(lines.size() == 4);  // header and the same three rows
  CHECK_THAT(read_text(md), Catch::Contains("`--repeat 2`"));
  CHECK(run_lab("bench " + scene + " --repeat 0 --out " + dir + "/o", dir + "/log0") == 2);
}
