// `grains plot RUN` (viewer-offline/plot.h): stats.csv drawn as PNG charts of the size asked
// for, a curve per solver, and bad folders or files refused with exit code 2.
#include <catch2/catch.hpp>
#include <filesystem>
#include <map>

#include "tests/support/png.h"
#include "tests/support/support.h"
#include "viewer-offline/plot.h"

using namespace grains;
namespace fs = std::filesystem;

namespace {

const char* kHeader =
    "frame,time,points,constraints,wall_ms,max_penetration,mean_penetration,max_strain,"
    "kinetic_energy,substeps,error\n";

// A stats.csv of `frames` rows whose energy rises and falls and whose strain is all zero.
std::string stats(int frames, double scale) {
  std::string s = kHeader;
  for (int f = 1; f <= frames; ++f) {
    char row[200];
    const double t = f / 24.0;
    std::snprintf(row, sizeof row, "%d,%g,100,0,1.000,%g,%g,0.0,%g,%d,%g\n", f, t,
                  scale * 0.01 * f, scale * 0.004 * f, scale * t * (2 - t), 2 + f % 3,
                  scale * 1e-3);
    s += row;
  }
  return s;
}

// The PNG's pixels as (r, g, b) counts, and its size.
std::map<std::tuple<int, int, int>, int> colours(const std::string& path, int& w, int& h) {
  const std::optional<test::Png> png = test::read_png(path);
  REQUIRE(png);
  w = png->w, h = png->h;
  std::map<std::tuple<int, int, int>, int> out;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const unsigned char* q = png->at(x, y);
      ++out[{q[0], q[1], q[2]}];
    }
  return out;
}

}  // namespace

TEST_CASE("plot draws stats.csv as charts of the size asked for", "[viewer][plot]") {
  const std::string dir = test::temp_dir("plot");
  test::write_file(dir, "stats.csv", stats(48, 1));
  REQUIRE(test::run_grains("plot " + dir + " --size 800x900 --quiet", dir + "/log") == 0);
  int w = 0, h = 0;
  auto c = colours(dir + "/stats.png", w, h);
  CHECK(w == 800);
  CHECK(h == 900);
  // not blank: mostly white paper, with text, grid and the first solver's blue curves
  const int white = c[{255, 255, 255}];
  CHECK(white < w * h * 0.97);
  CHECK(white > w * h * 0.5);
  const int blue = c[{31, 119, 180}];
  CHECK(blue > 4 * 2 * 300);  // at least four charts' 2-pixel curves across most of the width
  // --out names the file
  REQUIRE(test::run_grains("plot " + dir + " --out " + dir + "/other.png --size 400x400 --quiet",
                           dir + "/log") == 0);
  colours(dir + "/other.png", w, h);
  CHECK((w == 400 && h == 400));
}

TEST_CASE("plot draws a curve per solver of a run with several", "[viewer][plot]") {
  const std::string dir = test::temp_dir("plot_objects");
  fs::create_directories(dir + "/a");
  fs::create_directories(dir + "/b");
  test::write_file(dir + "/a", "stats.csv", stats(24, 1));
  test::write_file(dir + "/b", "stats.csv", stats(24, 0.5));
  REQUIRE(test::run_grains("plot " + dir + " --size 640x640 --quiet", dir + "/log") == 0);
  int w = 0, h = 0;
  auto c = colours(dir + "/stats.png", w, h);
  CHECK(c[{31, 119, 180}] > 500);  // a
  CHECK(c[{214, 39, 40}] > 500);   // b
}

TEST_CASE("plot of a real run", "[viewer][plot][cli]") {
  const std::string dir = test::temp_dir("plot_run");
  const std::string graph = test::write_file(dir, "g.json", R"({"grains_graph": 1, "name": "p",
    "fps": 24, "frames": 3, "nodes": [
    {"name": "src", "type": "source", "params": {"size": [0.2, 0.2, 0.2], "separation": 0.05,
      "center": [0, 0.5, 0]}},
    {"name": "g", "type": "force", "inputs": ["src"], "params": {"force": [0, -9.81, 0]}},
    {"name": "s", "type": "solver", "inputs": ["g"], "params": {}}]})");
  REQUIRE(test::run_grains("run " + graph + " --out " + dir + "/out --quiet", dir + "/log") == 0);
  REQUIRE(test::run_grains("plot " + dir + "/out --quiet", dir + "/log") == 0);
  int w = 0, h = 0;
  auto c = colours(dir + "/out/stats.png", w, h);
  CHECK((w == 1200 && h == 1300));
  CHECK(c[{31, 119, 180}] > 100);
}

TEST_CASE("plot refuses what is not a run's stats.csv with exit code 2", "[viewer][plot][cli]") {
  const std::string dir = test::temp_dir("plot_bad");
  const std::string log = dir + "/log";
  CHECK(test::run_grains("plot " + dir + "/none --quiet", log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("none: not a folder"));
  CHECK(test::run_grains("plot " + dir + " --quiet", log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("no stats.csv"));
  test::write_file(dir, "stats.csv", std::string(kHeader) + "1,0.04,1,0,1.0,0.0,0.0,0.0,x,1,0.0\n");
  CHECK(test::run_grains("plot " + dir + " --quiet", log) == 2);
  CHECK_THAT(test::read_text(log),
             Catch::Contains("stats.csv: line 2: kinetic_energy 'x' is not a number"));
  test::write_file(dir, "stats.csv", std::string(kHeader) + "1,0.04,1,0\n");
  CHECK(test::run_grains("plot " + dir + " --quiet", log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("line 2: 4 fields, the header has 11"));
  test::write_file(dir, "stats.csv", stats(2, 1));
  CHECK(test::run_grains("plot " + dir + " --size 10x10 --quiet", log) == 2);
  CHECK_FALSE(fs::exists(dir + "/stats.png"));
}
