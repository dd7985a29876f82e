// The command line (DESIGN §5): exit codes, frames and stats.csv as DESIGN §6 says.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "engine/geometry_io.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;
namespace fs = std::filesystem;

namespace {
const char* kGraph = R"({"grains_graph": 1, "name": "drop", "fps": 24, "frames": 4, "nodes": [
  {"name": "src", "type": "source", "params": {"shape": "box", "size": [0.3, 0.3, 0.3], "separation": 0.1, "center": [0, 1, 0]}},
  {"name": "g", "type": "force", "inputs": ["src"], "params": {"force": [0, -9.81, 0], "ignore_mass": true}},
  {"name": "ground", "type": "collider", "params": {"shape": "plane"}},
  {"name": "s", "type": "solver", "inputs": ["g"], "params": {"substeps": 2, "colliders": ["ground"]}}],
  "output": {"dir": "unused", "attributes": ["mass", "age", "force"]}})";
}

TEST_CASE("run writes every frame and stats.csv", "[cli]") {
  std::string dir = temp_dir("cli_run");
  std::string graph = write_file(dir, "drop.json", kGraph);
  std::string out = dir + "/out";
  REQUIRE(run_grains("run " + graph + " --out " + out + " --frames 3", dir + "/log") == 0);
  for (int f = 1; f <= 3; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "/frame_%04d.ply", f);
    REQUIRE(fs::exists(out + name));
  }
  CHECK_FALSE(fs::exists(out + "/frame_0004.ply"));  // --frames overrides the graph's 4
  for (auto& e : fs::directory_iterator(out)) CHECK(e.path().extension() != ".tmp");
  ParticleStore last = read_ply(out + "/frame_0003.ply");
  CHECK(last.size() == 27);
  CHECK(last.has("mass"));
  CHECK(last.has("force"));
  std::string stats = read_text(out + "/stats.csv");
  CHECK_THAT(stats, Catch::StartsWith("frame,time,points,constraints,wall_ms,max_penetration,"
                                      "mean_penetration,max_strain,kinetic_energy,substeps,error\n"));
  CHECK(std::count(stats.begin(), stats.end(), '\n') == 4);
  CHECK_THAT(stats, Catch::Contains("\n3,0.125,27,0,"));
  // not a terminal: one log line per frame
  std::string log = read_text(dir + "/log");
  CHECK_THAT(log, Catch::Contains("frame 1/3"));
  CHECK_THAT(log, Catch::Contains("frame 3/3"));
}

TEST_CASE("stats.csv writes every float column as a float, zeros and whole numbers too", "[cli]") {
  // a reader that infers column types (pandas) must read the same type from every run: the drop
  // has no constraints (max_strain all zero) and frame 24 ends at a whole second
  std::string dir = temp_dir("cli_stats_floats");
  std::string graph = write_file(dir, "drop.json", kGraph);
  REQUIRE(run_grains("run " + graph + " --out " + dir + "/out --frames 24 --quiet", dir + "/log") == 0);
  std::istringstream rows(read_text(dir + "/out/stats.csv"));
  std::string line;
  std::getline(rows, line);  // header
  int count = 0;
  for (; std::getline(rows, line); ++count) {
    INFO(line);
    std::vector<std::string> field;
    std::istringstream cells(line);
    for (std::string c; std::getline(cells, c, ',');) field.push_back(c);
    REQUIRE(field.size() == 11);
    // frame, points, constraints and substeps are counts; the rest are floats
    for (size_t k : {1, 4, 5, 6, 7, 8, 10})
      CHECK(field[k].find_first_of(".e") != std::string::npos);
    for (size_t k : {0, 2, 3, 9}) CHECK(field[k].find_first_of(".e") == std::string::npos);
  }
  CHECK(count == 24);
  CHECK_THAT(read_text(dir + "/out/stats.csv"), Catch::Contains("\n24,1.0,27,0,"));
}

TEST_CASE("output.formats writes VTK frames and their collection, which --overwrite replaces",
          "[cli][vtk]") {
  std::string dir = temp_dir("cli_formats");
  std::string text = kGraph;
  const std::string attrs = R"("attributes": ["mass", "age", "force"])";
  text.replace(text.find(attrs), attrs.size(), attrs + R"(, "formats": ["vtp"])");
  std::string graph = write_file(dir, "vtp.json", text);
  std::string out = dir + "/out";
  REQUIRE(run_grains("run " + graph + " --out " + out + " --frames 3 --quiet", dir + "/log") == 0);
  for (const char* f : {"frame_0001.vtp", "frame_0003.vtp", "frames.pvd", "stats.csv"}) {
    INFO(f);
    CHECK(fs::exists(out + "/" + f));
  }
  CHECK_FALSE(fs::exists(out + "/frame_0001.ply"));  // vtp alone
  const std::string pvd = read_text(out + "/frames.pvd");
  CHECK(std::count(pvd.begin(), pvd.end(), '\n') == 8);  // 5 lines of XML, 3 frames
  CHECK_THAT(pvd, Catch::Contains("timestep=\"0.125\" group=\"\" part=\"0\" file=\"frame_0003.vtp\""));
  // what the run wrote counts as its own: without --overwrite the folder is refused, with it
  // the .vtp frames and frames.pvd go with the rest
  CHECK(run_grains("run " + graph + " --out " + out + " --frames 1 --quiet", dir + "/log") == 2);
  REQUIRE(run_grains("run " + write_file(dir, "ply.json", kGraph) + " --out " + out +
                         " --frames 1 --quiet --overwrite",
                     dir + "/log") == 0);
  CHECK(fs::exists(out + "/frame_0001.ply"));
  CHECK_FALSE(fs::exists(out + "/frame_0001.vtp"));
  CHECK_FALSE(fs::exists(out + "/frames.pvd"));
  // a graph asking for a format there is none of is refused at load
  text.replace(text.find("[\"vtp\"]"), 7, "[\"vtk\"]");
  CHECK(run_grains("run " + write_file(dir, "vtk.json", text) + " --out " + dir + "/o2 --quiet",
                   dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains("vtk.json: /output/formats/0: unknown frame format 'vtk'"));
  CHECK_FALSE(fs::exists(dir + "/o2"));
}

TEST_CASE("quiet prints nothing and set overrides a parameter", "[cli]") {
  std::string dir = temp_dir("cli_set");
  std::string graph = write_file(dir, "drop.json", kGraph);
  REQUIRE(run_grains("run " + graph + " --out " + dir + "/a --frames 1 --quiet --set src.separation=0.15",
                     dir + "/log") == 0);
  CHECK(read_text(dir + "/log").empty());
  CHECK(read_ply(dir + "/a/frame_0001.ply").size() == 8);  // 0.3 m at 0.15 m: 2 per side
  CHECK(run_grains("run " + graph + " --out " + dir + "/b --set src.separation=-1", dir + "/log2") == 2);
  CHECK_THAT(read_text(dir + "/log2"), Catch::Contains("/nodes/0/params/separation"));
}

TEST_CASE("bad input exits with 2 and says where", "[cli]") {
  std::string dir = temp_dir("cli_bad");
  std::string bad = write_file(dir, "bad.json", std::string(kGraph).replace(std::string(kGraph).find("\"fps\": 24"), 9, "\"fps\": 0"));
  CHECK(run_grains("validate " + bad, dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains(bad + ": /fps: fps must lie between 0.001 and 1000000.0"));
  CHECK(run_grains("run " + bad + " --out " + dir + "/o", dir + "/log") == 2);
  CHECK_FALSE(fs::exists(dir + "/o"));  // refused before any frame
  CHECK(run_grains("run " + dir + "/missing.json", dir + "/log") == 2);
  CHECK(run_grains("run", dir + "/log") == 2);
  std::string good = write_file(dir, "good.json", kGraph);
  CHECK(run_grains("validate " + good, dir + "/log") == 0);
}

TEST_CASE("nodes prints every type's parameters from their declarations", "[cli]") {
  std::string dir = temp_dir("cli_nodes");
  REQUIRE(run_grains("nodes", dir + "/log") == 0);
  std::string all = read_text(dir + "/log");
  for (const char* t : {"source", "group", "force", "merge", "kill", "collider", "solver", "grains"})
    CHECK_THAT(all, Catch::Contains(std::string(t) + ": "));
  REQUIRE(run_grains("nodes grains --markdown", dir + "/md") == 0);
  std::string md = read_text(dir + "/md");
  CHECK_THAT(md, Catch::StartsWith("## grains"));
  CHECK_THAT(md, Catch::Contains("| `constraint_iterations` | int | `10` |"));
  CHECK_THAT(md, Catch::Contains("`repulsionweight`"));
  CHECK(run_grains("nodes nosuch", dir + "/log") == 2);
}

TEST_CASE("a graph's frames are bit-identical for 1 and 2 threads", "[cli][determinism]") {
  // Gather-style kernels and static schedules: the thread count must not change a single bit,
  // here on breaking_wall: grains of two sizes, constraints that break, mass-shock, a collider.
  std::string dir = temp_dir("cli_threads");
  std::string graph = source_dir() + "/graphs/breaking_wall.json";
  REQUIRE(run_grains("run " + graph + " --frames 8 --quiet --threads 1 --out " + dir + "/t1", dir + "/log") == 0);
  REQUIRE(run_grains("run " + graph + " --frames 8 --quiet --threads 2 --out " + dir + "/t2", dir + "/log") == 0);
  for (int f = 1; f <= 8; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "/frame_%04d.ply", f);
    INFO(name);
    CHECK(read_text(dir + "/t1" + name) == read_text(dir + "/t2" + name));
  }
  // stats.csv too, but for its wall_ms column: equal grains (column_collapse.json, 2,640 grains
  // in three blocks of 1,024 by frame 4) take the parallel block-summed penetration scan,
  // breaking_wall's two sizes the general search
  const std::string collapse = source_dir() + "/graphs/column_collapse.json --frames 4 --quiet";
  REQUIRE(run_grains("run " + collapse + " --threads 1 --out " + dir + "/d1", dir + "/log") == 0);
  REQUIRE(run_grains("run " + collapse + " --threads 2 --out " + dir + "/d2", dir + "/log") == 0);
  auto without_wall = [](const std::string& csv) {
    std::string out;
    for (const std::string& line : split(csv, '\n')) {
      std::vector<std::string> cells = split(line, ',');
      REQUIRE(cells.size() == 11);  // frame,time,points,constraints,wall_ms,...,substeps,error
      cells.erase(cells.begin() + 4);
      for (const std::string& c : cells) out += c + ",";
      out += "\n";
    }
    return out;
  };
  for (const char* run : {"/t", "/d"}) {
    INFO(run);
    const std::string a = read_text(dir + run + "1/stats.csv");
    const std::string b = read_text(dir + run + "2/stats.csv");
    REQUIRE(a.size() > 100);
    CHECK(without_wall(a) == without_wall(b));
  }
}
