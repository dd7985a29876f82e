// What the programs print on stderr at each level (cli/log.h): --quiet only errors and warnings,
// the default progress and what was written, --verbose each phase and each frame's detail; an
// error reads the same at every level.
#include <catch2/catch.hpp>
#include <filesystem>

#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;

namespace {
const char* kGraph = R"({"grains_graph": 1, "name": "drop", "fps": 24, "frames": 3, "nodes": [
  {"name": "src", "type": "source", "params": {"shape": "box", "size": [0.3, 0.3, 0.3], "separation": 0.1, "center": [0, 1, 0]}},
  {"name": "g", "type": "force", "inputs": ["src"], "params": {"force": [0, -9.81, 0], "ignore_mass": true}},
  {"name": "ground", "type": "collider", "params": {"shape": "plane"}},
  {"name": "s", "type": "solver", "inputs": ["g"], "params": {"substeps": 2, "colliders": ["ground"]}}],
  "output": {"dir": "unused"}})";

bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}
}  // namespace

TEST_CASE("run: --quiet prints nothing, the default progress, --verbose each frame's detail",
          "[cli][log]") {
  const std::string dir = temp_dir("log_levels");
  const std::string graph = write_file(dir, "drop.json", kGraph);

  REQUIRE(run_grains("run " + graph + " --quiet --out " + dir + "/q", dir + "/quiet.log") == 0);
  CHECK(read_text(dir + "/quiet.log").empty());

  // not a terminal: the first and the last frame, with the time taken and left, then the folder;
  // 8 frames of 27 grains take far less than the 5 s between two progress lines
  REQUIRE(run_grains("run " + graph + " --frames 8 --out " + dir + "/d", dir + "/default.log") ==
          0);
  const std::string normal = read_text(dir + "/default.log");
  INFO(normal);
  CHECK(has(normal, "frame 1/8  points 27  "));
  CHECK(has(normal, "frame 8/8  points 27  t 0.3333 s  "));  // the simulated time, 8 / 24 fps
  CHECK(has(normal, "  elapsed "));
  CHECK(has(normal, "  left 0.0 s\n"));  // the last frame
  CHECK_FALSE(has(normal, "frame 4/8"));
  CHECK(has(normal, "precision: solver 's', frame 1:"));
  CHECK(has(normal, "wrote " + dir + "/d\n"));
  CHECK_FALSE(has(normal, "solver 's': 27 points"));  // the detail is --verbose's

  REQUIRE(run_grains("run " + graph + " --verbose --out " + dir + "/v", dir + "/verbose.log") == 0);
  const std::string verbose = read_text(dir + "/verbose.log");
  INFO(verbose);
  CHECK(has(verbose, "graph " + graph + ": 4 nodes, 1 solvers, 3 frames at 24 fps\n"));
  CHECK(has(verbose, "writing frames to " + dir + "/v\n"));
  for (const char* f : {"frame 1/3", "frame 2/3", "frame 3/3"}) CHECK(has(verbose, f));
  // frame 2: every grain falls freely, 2 substeps, no error control's refinement
  CHECK(has(verbose, "frame 2 solver 's': 27 points, 0 constraints, 2 substeps, error "));
  CHECK(has(verbose, ", kinetic energy "));
  CHECK(has(verbose, "wrote " + dir + "/v\n"));

  CHECK(run_grains("run " + graph + " --quiet --verbose --out " + dir + "/qv", dir + "/qv.log") ==
        2);
  CHECK(has(read_text(dir + "/qv.log"), "--quiet excludes --verbose"));
}

TEST_CASE("an error prints the same line with --quiet and exits with 2", "[cli][log]") {
  const std::string dir = temp_dir("log_error");
  const std::string missing = dir + "/missing.json";
  CHECK(run_grains("run " + missing + " --quiet", dir + "/quiet.log") == 2);
  CHECK(run_grains("run " + missing, dir + "/default.log") == 2);
  const std::string quiet = read_text(dir + "/quiet.log");
  CHECK_THAT(quiet, Catch::StartsWith("grains: error: " + missing));
  CHECK(quiet == read_text(dir + "/default.log"));
  CHECK(run_grains("frobnicate", dir + "/unknown.log") == 2);
  CHECK_THAT(read_text(dir + "/unknown.log"),
             Catch::StartsWith("grains: unknown command 'frobnicate' (commands: run, "));
}

TEST_CASE("cook and render take --quiet and --verbose", "[cli][log]") {
  const std::string dir = temp_dir("log_cook_render");
  const std::string graph = write_file(dir, "drop.json", kGraph);
  REQUIRE(run_grains("run " + graph + " --quiet --out " + dir + "/frames", dir + "/run.log") == 0);

  const std::string in = dir + "/frames/frame_0003.ply";
  REQUIRE(
      run_grains("cook grains --in " + in + " --frames 2 --ground 0 --quiet --out " + dir + "/cq",
                 dir + "/cq.log") == 0);
  CHECK(read_text(dir + "/cq.log").empty());
  REQUIRE(
      run_grains("cook grains --in " + in + " --frames 2 --ground 0 --verbose --out " + dir + "/cv",
                 dir + "/cv.log") == 0);
  const std::string cook = read_text(dir + "/cv.log");
  INFO(cook);
  CHECK(has(cook, "cook grains: frame 1: 27 points"));
  CHECK(has(cook, "cook grains: frame 2: 27 points"));
  CHECK(has(cook, "cooked grains on 27 points; wrote " + dir + "/cv\n"));

  const std::string render = "render " + dir + "/frames --size 32x24 --supersample 1 --out ";
  REQUIRE(run_grains(render + dir + "/rq --quiet", dir + "/rq.log") == 0);
  CHECK(read_text(dir + "/rq.log").empty());
  REQUIRE(run_grains(render + dir + "/rv --verbose", dir + "/rv.log") == 0);
  const std::string rendered = read_text(dir + "/rv.log");
  INFO(rendered);
  CHECK(has(rendered, "render: frame 3 (3/3): 27 grains in "));
  CHECK(has(rendered, "render: contact sheet " + dir + "/rv/contact_sheet.png\n"));
}

TEST_CASE("the lab's commands take --quiet and --verbose", "[lab][log]") {
  const std::string dir = temp_dir("log_lab");
  for (const char* command : {"bench", "features", "laws"}) {
    INFO(command);
    REQUIRE(run_lab(std::string(command) + " --help", dir + "/help.log") == 0);
    const std::string help = read_text(dir + "/help.log");
    CHECK(has(help, "--quiet"));
    CHECK(has(help, "--verbose"));
  }
}
