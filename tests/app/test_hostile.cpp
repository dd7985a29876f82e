// Hostile input (issue "hostile input"): numbers that are not finite are refused where they are
// read (file, element, index; exit 2), and one that arises during a run stops it (exit 1) naming
// the frame, substep, node and point, with the frames before it kept; thread counts are bounded.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>

#include "engine/geometry_io.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;
namespace fs = std::filesystem;

namespace {
// a drop of 27 grains; FORCE_Y replaced by each test
const char* kDrop = R"({"grains_graph": 1, "name": "drop", "fps": 24, "frames": 4, "nodes": [
  {"name": "src", "type": "source", "params": {"shape": "box", "size": [0.3, 0.3, 0.3], "separation": 0.1, "center": [0, 1, 0]}},
  {"name": "push", "type": "force", "inputs": ["src"], "params": {"force": [0, FORCE_Y, 0], "ignore_mass": true DRAG}},
  {"name": "ground", "type": "collider", "params": {"shape": "plane"}},
  {"name": "s", "type": "solver", "inputs": ["push"], "params": {"substeps": 2, "colliders": ["ground"]}}],
  "output": {"dir": "unused"}})";

std::string drop(const std::string& force_y, const std::string& drag = "") {
  std::string g = kDrop;
  g.replace(g.find("FORCE_Y"), 7, force_y);
  g.replace(g.find(" DRAG"), 5, drag.empty() ? "" : ", \"drag\": " + drag);
  return g;
}

// a PLY of three points whose coordinate `bad` (x, y or z) of point 1 is `value`
std::string ascii_ply(const std::string& bad, const std::string& value) {
  std::string rows[3] = {"0 0.5 0", "0.1 0.5 0", "0.2 0.5 0"};
  std::string r = rows[1];
  const int axis = bad == "x" ? 0 : bad == "y" ? 1 : 2;
  std::vector<std::string> c = split(r, ' ');
  c[axis] = value;
  rows[1] = c[0] + " " + c[1] + " " + c[2];
  return "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n" +
         rows[0] + "\n" + rows[1] + "\n" + rows[2] + "\n";
}
}  // namespace

TEST_CASE("a state that stops being finite stops the run naming frame, substep, node, point",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_inf_state");
  // a drag of 1e30 from frame 3 (a valid number): the grains' speed, then their force, overflow
  std::string graph = write_file(dir, "g.json", drop("-9.81", "\"$F >= 3 ? 1e30 : 0\""));
  std::string out = dir + "/out";
  CHECK(run_grains("run " + graph + " --out " + out + " --quiet", dir + "/log") == 1);
  const std::string log = read_text(dir + "/log");
  CHECK_THAT(log, Catch::Contains("frame 3, substep 2 of 2, node 'push': point id 0 is not "
                                  "finite: force ("));
  CHECK_THAT(log, Catch::Contains("inf"));
  // the frames before it are kept, whole; nothing of frame 3
  CHECK(read_ply(out + "/frame_0002.ply").size() == 27);
  CHECK_FALSE(fs::exists(out + "/frame_0003.ply"));
  const std::string stats = read_text(out + "/stats.csv");
  CHECK(std::count(stats.begin(), stats.end(), '\n') == 3);  // header and frames 1, 2
  CHECK(stats.find("nan") == std::string::npos);
  CHECK(stats.find("inf") == std::string::npos);
}

TEST_CASE("an expression that turns NaN is refused at its frame, earlier frames kept",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_nan_force");
  // sqrt(2.9 - F): finite through frame 2 (F = 2.5 at its second substep), NaN from frame 3
  std::string graph = write_file(dir, "g.json", drop("\"-sqrt(2.9 - $F)\""));
  std::string out = dir + "/out";
  CHECK(run_grains("run " + graph + " --out " + out + " --quiet", dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains(graph + ": /nodes/1/params/force: frame 3: 'force' must be a finite "
                                     "number, got nan"));
  CHECK(read_ply(out + "/frame_0002.ply").size() == 27);
  CHECK_FALSE(fs::exists(out + "/frame_0003.ply"));
}

TEST_CASE("forces beyond the float range stop the run instead of writing infinities",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_huge_force");
  struct Case {
    std::string force, drag;
    int rc;
  };
  for (const Case& c :
       std::vector<Case>{{"1e308", "", 2}, {"-9.81", "1e30", 1}, {"\"1 / ($F - 1)\"", "", 2},
                         {"\"$F >= 3 ? 1e39 : -9.81\"", "", 2}}) {
    std::string graph = write_file(dir, "g.json", drop(c.force, c.drag));
    INFO(c.force << " drag " << c.drag);
    CHECK(run_grains("run " + graph + " --out " + dir + "/out --quiet", dir + "/log") == c.rc);
    // a drag of 1e30 flings the grains past 1e25 m within a frame: the precision check
    // (grains that far cannot be told apart) or the finiteness check stops the run first
    if (c.rc == 1)
      CHECK_THAT(read_text(dir + "/log"),
                 Catch::Contains("is not finite") || Catch::Contains("cannot be told apart"));
    else
      CHECK_THAT(read_text(dir + "/log"), Catch::Contains("/nodes/1/params/force"));
    if (fs::exists(dir + "/out"))
      for (auto& e : fs::directory_iterator(dir + "/out")) {
        if (e.path().extension() != ".ply") continue;
        ParticleStore f = read_ply(e.path().string());  // refuses a non-finite number
        CHECK(f.size() == 27);
      }
    fs::remove_all(dir + "/out");
  }
}

TEST_CASE("a PLY or OBJ with a coordinate that is not finite is refused with its place",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_ply");
  for (const char* axis : {"x", "y", "z"})
    for (const char* value : {"nan", "inf", "-inf", "1e39"}) {
      std::string ply = write_file(dir, "p.ply", ascii_ply(axis, value));
      INFO(axis << " = " << value);
      CHECK(run_grains("cook grains --in " + ply + " --out " + dir + "/o", dir + "/log") == 2);
      const std::string log = read_text(dir + "/log");
      CHECK_THAT(log, Catch::Contains(ply + ": vertex 1: property '" + axis + "' is"));
      CHECK_FALSE(fs::exists(dir + "/o/frame_0001.ply"));
      CHECK_THROWS_AS(read_ply(ply), GeometryError);
      CHECK_THROWS_AS(read_mesh(ply), GeometryError);
    }
  std::string obj = write_file(dir, "m.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n");
  CHECK_THROWS_WITH(read_mesh(obj), Catch::Contains(obj + ":2: vertex coordinate 'nan' is NaN"));
  // a NaN rest length on an edge
  std::string edges = write_file(dir, "e.ply",
                                 "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
                                 "property float y\nproperty float z\nelement edge 1\n"
                                 "property int vertex1\nproperty int vertex2\n"
                                 "property float restlength\nend_header\n0 0 0\n1 0 0\n0 1 nan\n");
  CHECK_THROWS_WITH(read_ply(edges), Catch::Contains("edge 0: property 'restlength' is NaN"));
}

TEST_CASE("thread counts are bounded with a plain message", "[cli][hostile]") {
  std::string dir = temp_dir("hostile_threads");
  std::string graph = write_file(dir, "g.json", drop("-9.81"));
  for (const char* t : {"0", "65535", "-3"}) {
    INFO("--threads " << t);
    CHECK(run_grains("run " + graph + " --out " + dir + "/o --threads " + t, dir + "/log") == 2);
    CHECK_THAT(read_text(dir + "/log"), Catch::Contains("not in range 1 to 1024"));
    CHECK_FALSE(fs::exists(dir + "/o"));
  }
  CHECK(run_grains("run " + graph + " --out " + dir + "/o --quiet --threads 1024 --frames 1",
                   dir + "/log") == 0);
}

TEST_CASE("numbers are checked where they are read: literals, expressions and keys",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_numbers");
  struct Case {
    std::string from, to;  // replaced in the drop graph
    bool at_load;          // refused by validate, else at the frame it appears
    std::string message;
  };
  const std::vector<Case> cases = {
      // a literal integer beyond int used to wrap to 0 iterations
      {"\"substeps\": 2", "\"substeps\": 2147483648", true,
       "/nodes/3/params/substeps: 'substeps' must be at most 2147483647 in size, got 2147483648"},
      {"\"frames\": 4", "\"frames\": 1000000000000", true,
       "/frames: frames must be at most 2147483647, got 1000000000000"},
      // expressions: checked each time they are evaluated, with the frame
      {"\"substeps\": 2", "\"substeps\": \"-$F\"", false,
       "/nodes/3/params/substeps: frame 1: 'substeps' must be at least 1, got -1"},
      {"\"substeps\": 2", "\"substeps\": \"1/0\"", false,
       "/nodes/3/params/substeps: frame 1: 'substeps' must be a finite number, got inf"},
      {"\"separation\": 0.1", "\"separation\": \"0.1 - 0.05 * $F\"", false,
       "/nodes/0/params/separation: frame 2: 'separation' must be greater than 0, got 0"},
      // keys: a drag that turns negative would put energy in
      {"\"ignore_mass\": true", "\"ignore_mass\": true, \"drag\": {\"keys\": [[0, 0], [2, -100]]}",
       false, "/nodes/1/params/drag: frame 1: 'drag' must be at least 0, got -"},
  };
  for (const Case& c : cases) {
    std::string text = drop("-9.81");
    REQUIRE(text.find(c.from) != std::string::npos);
    text.replace(text.find(c.from), c.from.size(), c.to);
    std::string graph = write_file(dir, "g.json", text);
    INFO(c.to);
    CHECK(run_grains("validate " + graph, dir + "/vlog") == (c.at_load ? 2 : 0));
    CHECK(run_grains("run " + graph + " --quiet --out " + dir + "/o", dir + "/log") == 2);
    CHECK_THAT(read_text(dir + "/log"), Catch::Contains(graph + ": " + c.message));
    if (c.at_load) CHECK_THAT(read_text(dir + "/vlog"), Catch::Contains(c.message));
    if (c.at_load) CHECK_FALSE(fs::exists(dir + "/o"));
    fs::remove_all(dir + "/o");
  }
}

TEST_CASE("names that become paths are plain; nothing is written outside the named folders",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_paths");
  for (const char* name : {"../escaped", "../../escaped", "a/b", ".hidden", "-x", "a b", ""}) {
    std::string text = drop("-9.81");
    const std::string solver = "\"name\": \"s\", \"type\": \"solver\"";
    text.replace(text.find(solver), solver.size(),
                 std::string("\"name\": \"") + name + "\", \"type\": \"solver\"");
    std::string graph = write_file(dir, "g.json", text);
    INFO("solver name '" << name << "'");
    CHECK(run_grains("validate " + graph, dir + "/log") == 2);
    CHECK_THAT(read_text(dir + "/log"), Catch::Contains(graph + ": /nodes/3/name: "));
    CHECK(run_grains("run " + graph + " --out " + dir + "/o", dir + "/log") == 2);
    CHECK_FALSE(fs::exists(dir + "/o"));
  }
  CHECK_FALSE(fs::exists(dir + "/escaped"));  // o/../escaped
  CHECK_FALSE(fs::exists(fs::path(dir).parent_path() / "escaped"));
  // a video's folder must exist: render makes no folders but its own --out
  std::string graph = write_file(dir, "g.json", drop("-9.81"));
  REQUIRE(run_grains("run " + graph + " --quiet --frames 1 --out " + dir + "/frames",
                     dir + "/log") == 0);
  const std::string video = dir + "/missing/deeper/v.gif";
  CHECK(run_grains("render " + dir + "/frames --size 32x24 --video " + video, dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains("the folder " + dir + "/missing/deeper does not exist"));
  CHECK_FALSE(fs::exists(dir + "/missing"));
}

TEST_CASE("a folder or a device where a file is expected is refused by name", "[cli][hostile]") {
  std::string dir = temp_dir("hostile_files");
  fs::create_directories(dir + "/folder.json");
  CHECK(run_grains("run " + dir + "/folder.json --out " + dir + "/o", dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains(dir + "/folder.json: the graph file is a folder, not a file"));
  CHECK(run_grains("validate /dev/zero", dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains("/dev/zero: the graph file is not a regular file"));
  CHECK(run_grains("cook grains --in " + dir + "/folder.json --out " + dir + "/o", dir + "/log") ==
        2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("is a folder, not a file"));
  CHECK_THROWS_WITH(read_ply("/dev/zero"), Catch::Contains("is not a regular file"));
  fs::create_directories(dir + "/m.obj");
  CHECK_THROWS_WITH(read_mesh(dir + "/m.obj"), Catch::Contains("m.obj: is a folder, not a file"));
  CHECK_FALSE(fs::exists(dir + "/o"));
}

TEST_CASE("a used output folder is refused unless asked to overwrite, which clears old frames",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_reuse");
  std::string graph = write_file(dir, "g.json", drop("-9.81"));
  const std::string out = dir + "/o";
  REQUIRE(run_grains("run " + graph + " --quiet --frames 3 --out " + out, dir + "/log") == 0);
  write_file(out, "frame_0009.ply.tmp", "partial");  // as a killed run leaves it
  write_file(out, "notes.txt", "mine");
  CHECK(run_grains("run " + graph + " --quiet --frames 2 --out " + out, dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains(out + ": the output folder is not empty"));
  CHECK(fs::exists(out + "/frame_0003.ply"));  // refused: nothing touched
  CHECK(run_grains("run " + graph + " --quiet --frames 2 --overwrite --out " + out, dir + "/log") ==
        0);
  CHECK(fs::exists(out + "/frame_0002.ply"));
  CHECK_FALSE(fs::exists(out + "/frame_0003.ply"));  // the earlier run's third frame is gone
  CHECK_FALSE(fs::exists(out + "/frame_0009.ply.tmp"));
  CHECK(read_text(out + "/notes.txt") == "mine");  // not the run's: kept
  const std::string stats = read_text(out + "/stats.csv");
  CHECK(std::count(stats.begin(), stats.end(), '\n') == 3);
}

TEST_CASE("command-line numbers that are not finite are refused by option", "[cli][hostile]") {
  std::string dir = temp_dir("hostile_options");
  std::string ply = write_file(dir, "p.ply", ascii_ply("x", "0.05"));
  CHECK(run_grains("cook grains --in " + ply + " --ground nan --out " + dir + "/o", dir + "/log") ==
        2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("--ground: 'nan' is not a finite number"));
  std::string graph = write_file(dir, "g.json", drop("-9.81"));
  REQUIRE(run_grains("run " + graph + " --quiet --frames 1 --out " + dir + "/f", dir + "/log") ==
          0);
  CHECK(run_grains("render " + dir + "/f --size 32x24 --camera 0,1,5,0,0,0,nan", dir + "/log") ==
        2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("'nan' is not a finite number"));
}

TEST_CASE("emission past the point budget is refused with the numbers before allocating",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_budget");
  struct Case {
    std::string from, to, args, message;
  };
  const std::vector<Case> cases = {
      // (within the reach of floats: a separation of 1e-9 or a box of 1e30 m is refused before,
      // for its precision: "far from the origin" below)
      {"\"separation\": 0.1", "\"separation\": 1e-4", "",
       "node 'src': a box of 3"},  // 3,000 a side, as the float division gives it
      {"\"size\": [0.3, 0.3, 0.3]", "\"size\": [1e4, 1e4, 1e4]", "", "more than the budget"},
      {"\"separation\": 0.1,", "\"separation\": 0.1, \"emission\": \"rate\", \"rate\": 1e12,", "",
       "emitting 1000000000000 grains a second"},
      {"\"separation\": 0.1", "\"separation\": 0.1", "--max-points 26",
       "would bring the points to 27, more than the budget of 26"},
  };
  for (const Case& c : cases) {
    std::string text = drop("-9.81");
    text.replace(text.find(c.from), c.from.size(), c.to);
    std::string graph = write_file(dir, "g.json", text);
    INFO(c.to << " " << c.args);
    CHECK(run_grains("run " + graph + " --quiet --out " + dir + "/o " + c.args, dir + "/log") == 2);
    CHECK_THAT(read_text(dir + "/log"), Catch::Contains(c.message) &&
                                            Catch::Contains("more than the budget of") &&
                                            Catch::Contains("raise it with --max-points"));
    fs::remove_all(dir + "/o");
  }
  std::string graph = write_file(dir, "g.json", drop("-9.81"));
  CHECK(run_grains("run " + graph + " --quiet --frames 1 --max-points 27 --out " + dir + "/o",
                   dir + "/log") == 0);
}

TEST_CASE("an output attribute no node makes is refused by validate with its pointer",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_attributes");
  const std::string kOutput = "\"output\": {\"dir\": \"unused\"}";
  auto graph_with = [&](const std::string& attributes, const std::string& extra_node) {
    std::string text = drop("-9.81");
    text.replace(text.find(kOutput), kOutput.size(),
                 "\"output\": {\"dir\": \"unused\", \"attributes\": [" + attributes + "]}");
    if (!extra_node.empty()) {  // between the force and the solver
      text.replace(text.find("{\"name\": \"ground\""), 0, extra_node + ",\n  ");
      text.replace(text.find("[\"push\"], \"params\": {\"substeps\""), 8, "[\"g\"]");
    }
    return write_file(dir, "g.json", text);
  };
  CHECK(run_grains("validate " + graph_with("\"mass\", \"colour\"", ""), dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains("/output/attributes/1: unknown point attribute 'colour'") &&
                 Catch::Contains("pscale"));
  // a group's attribute exists once a group node makes it; impact data and known names pass
  const std::string group =
      R"({"name": "g", "type": "group", "inputs": ["push"], "params": {"group_name": "top"}})";
  CHECK(run_grains("validate " + graph_with("\"group_top\"", ""), dir + "/log") == 2);
  CHECK(run_grains("validate " + graph_with("\"group_top\", \"impactN\", \"age\"", group),
                   dir + "/log") == 0);
  // a source that reads a file may hold any attribute: checked when its first frame is written
  write_file(dir, "p.ply", ascii_ply("x", "0.1"));
  std::string text = drop("-9.81");
  text.replace(text.find("\"shape\": \"box\""), 14, "\"shape\": \"file\", \"file\": \"p.ply\"");
  text.replace(text.find(kOutput), kOutput.size(),
               "\"output\": {\"dir\": \"unused\", \"attributes\": [\"colour\"]}");
  std::string file_graph = write_file(dir, "f.json", text);
  CHECK(run_grains("validate " + file_graph, dir + "/log") == 0);
  CHECK(run_grains("run " + file_graph + " --quiet --out " + dir + "/o", dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("cannot write attribute 'colour'"));
}

TEST_CASE("far from the origin the run states its precision, warns, then refuses with numbers",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_far");
  auto run_at = [&](const std::string& x) {
    std::string text = drop("-9.81");
    text.replace(text.find("\"center\": [0, 1, 0]"), 19, "\"center\": [" + x + ", 1, 0]");
    std::string graph = write_file(dir, "g.json", text);
    fs::remove_all(dir + "/o");
    return run_grains("run " + graph + " --frames 2 --out " + dir + "/o", dir + "/log");
  };
  // grains of radius 0.05 m: floats resolve 1.2e-7 m at 1.1 m, 6.1e-5 m at 1000 m (above a
  // thousandth of the radius), 1 m at 1e7 m (20 radii: a pile would fall onto a few positions)
  CHECK(run_at("0") == 0);
  std::string log = read_text(dir + "/log");
  CHECK_THAT(log, Catch::Contains("precision: solver 's', frame 1: points reach 1.091 m from the "
                                  "origin, where positions are resolved to 1.19e-07 m"));
  CHECK(log.find("warning") == std::string::npos);
  CHECK(run_at("1000") == 0);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains("grains: warning: solver 's', frame 1: points reach 1000 m") &&
                 Catch::Contains("resolved to 6.1e-05 m, 0.00122 of the smallest grain radius "
                                 "0.05 m") &&
                 Catch::Contains("within 512 m they would be"));
  // a source placed there is refused at load, naming its parameter
  CHECK(run_at("1e7") == 2);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains("/nodes/0/params/center: its grains would lie up to 1e+07 m from the "
                             "origin, where floats cannot tell grains of radius 0.05 m apart; "
                             "keep the shape within 6.554e+04 m of it"));
  CHECK_FALSE(fs::exists(dir + "/o/frame_0001.ply"));
  // grains that get there stop the run at that frame: pushed up at 1e9 m/s^2, 8.7e5 m in a frame
  std::string graph = write_file(dir, "g.json", drop("1e9"));
  fs::remove_all(dir + "/o");
  CHECK(run_grains("run " + graph + " --frames 2 --out " + dir + "/o", dir + "/log") == 1);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains("frame 1, solver 's': a point lies ") &&
                 Catch::Contains("smallest grain radius 0.05 m: grains there cannot be told apart; "
                                 "keep the scene within 6.554e+04 m of the origin"));
  CHECK_FALSE(fs::exists(dir + "/o/frame_0001.ply"));
}

TEST_CASE("a write the system refuses ends the run with exit 1 and its reason, frames kept",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_full");
  // ten grains a frame: frames grow by 320 bytes; a file-size limit of 1.5 KB (ulimit -f 3, in
  // 512-byte blocks) refuses a frame's write as a full disk would, with SIGXFSZ ignored
  std::string text = drop("-9.81");
  text.replace(text.find("\"separation\": 0.1"), 17,
               "\"separation\": 0.1, \"emission\": \"rate\", \"rate\": 240");
  text.replace(text.find("\"frames\": 4"), 11, "\"frames\": 12");
  std::string graph = write_file(dir, "g.json", text);
  std::string out = dir + "/out";
  const std::string cmd = "sh -c 'trap \"\" XFSZ; ulimit -f 3; exec " + std::string(GRAINS_BINARY) +
                          " run " + graph + " --quiet --out " + out + "' > " + dir + "/log 2>&1";
  int rc = std::system(cmd.c_str());
  REQUIRE(WIFEXITED(rc));
  CHECK(WEXITSTATUS(rc) == 1);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains("grains: failed: " + out + "/frame_00") &&
                 Catch::Contains(": cannot write (File too large)"));
  // every frame written is whole and has its stats row; nothing half-written stays
  int frames = 0;
  while (fs::exists(out + "/frame_" + std::string(frames + 1 < 10 ? "000" : "00") +
                    std::to_string(frames + 1) + ".ply"))
    ++frames;
  CHECK(frames >= 1);
  CHECK(frames < 12);
  for (int f = 1; f <= frames; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "/frame_%04d.ply", f);
    CHECK(read_ply(out + name).size() == size_t(10 * f));
  }
  const std::string stats = read_text(out + "/stats.csv");
  CHECK(std::count(stats.begin(), stats.end(), '\n') == frames + 1);
  CHECK(stats.back() == '\n');
  for (const auto& e : fs::directory_iterator(out)) CHECK(e.path().extension() != ".tmp");
}

TEST_CASE("an output folder that cannot be made is refused before any frame, with the reason",
          "[cli][hostile]") {
  std::string dir = temp_dir("hostile_unwritable");
  std::string graph = write_file(dir, "g.json", drop("-9.81"));
  write_file(dir, "plain", "a file");
  CHECK(run_grains("run " + graph + " --quiet --out " + dir + "/plain/x", dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"),
             Catch::Contains(dir + "/plain/x: cannot make the output folder (Not a directory)"));
  write_file(dir, "p.ply", ascii_ply("x", "0.1"));
  CHECK(run_grains("cook grains --in " + dir + "/p.ply --out " + dir + "/plain/x", dir + "/log") ==
        2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("cannot make the output folder"));
}
