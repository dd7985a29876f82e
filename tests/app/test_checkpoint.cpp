// grains run --checkpoint-every / --resume: a run killed part-way and resumed from its last
// checkpoint writes the same files, bit for bit, as a run that was never stopped.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <thread>
#include <tuple>

#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;
namespace fs = std::filesystem;

namespace {

// A pour with everything that carries state from one frame to the next: a source emitting at a
// rate (the part of a grain it owes, its random draws), a once-source of a rigid sheet (shape
// matching's rest shapes, explicit constraints), pins on the sheet set by a target node (which
// owns targetstiffness), friction's contact history, the Verlet rows, a collider moving under
// an expression with collision feedback, and error control's substep count.
const char* kScene = R"JSON({"grains_graph": 1, "name": "resume", "fps": 24, "frames": 18, "seed": 5,
  "nodes": [
  {"name": "pour", "type": "source", "params": {"emission": "rate", "rate": 600,
    "shape": "box", "center": [0, 0.35, 0], "size": [0.12, 0.04, 0.12], "separation": 0.02,
    "velocity": [0, -0.5, 0]}},
  {"name": "sheet", "type": "source", "params": {"shape": "grid", "center": [0.25, 0.15, 0],
    "size": [0.16, 0, 0.16], "separation": 0.02, "connect_radius": 1.5, "birth_frame": 3}},
  {"name": "pin", "type": "target", "inputs": ["sheet"], "params": {"stiffness": 0.2,
    "translate": ["0", "0.1 * sin($T * 6)", "0"]}},
  {"name": "g", "type": "grains", "inputs": ["pour", "pin"], "params": {
    "enable_rigid_shape_matching": true, "enable_collision_feedback": true,
    "add_impact_data": true}},
  {"name": "ground", "type": "collider", "params": {"shape": "plane"}},
  {"name": "paddle", "type": "collider", "params": {"shape": "box", "size": [0.3, 0.05, 0.05],
    "translate": ["-0.1 + 0.2 * $T", "0.04", "0"]}},
  {"name": "s", "type": "solver", "inputs": ["g"], "params": {"max_substeps": 16, "colliders": ["ground", "paddle"]}}],
  "output": {"dir": "unused", "attributes": ["targetP", "impact", "impactimpulse"],
             "formats": ["ply", "vtp"]}})JSON";

// The child `grains ARGS` (the program itself, no shell between: the kill must reach it),
// killed (SIGKILL) as soon as `dir`'s stats.csv holds `rows` frames; returns the frames it had
// written, or -1 when it ended by itself first.
int run_and_kill(const std::vector<std::string>& args, const std::string& dir, int rows) {
  std::vector<std::string> words = {GRAINS_BINARY};
  words.insert(words.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& w : words) argv.push_back(w.data());
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    const int null = open("/dev/null", O_WRONLY);
    dup2(null, 1);
    dup2(null, 2);
    execv(argv[0], argv.data());
    _exit(127);
  }
  auto frames_written = [&] {
    int lines = 0;
    for (char c : read_text(dir + "/stats.csv")) lines += c == '\n';
    return lines - 1;
  };
  int status = 0;
  while (waitpid(pid, &status, WNOHANG) == 0) {
    if (frames_written() >= rows) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      return frames_written();
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return -1;
}

// stats.csv without its wall_ms column (the one field that is a measured time)
std::string stats_without_time(const std::string& dir) {
  std::string out;
  for (const std::string& line : split(read_text(dir + "/stats.csv"), '\n')) {
    const std::vector<std::string> f = split(line, ',');
    for (size_t k = 0; k < f.size(); ++k)
      if (k != 4) out += f[k] + (k + 1 < f.size() ? "," : "\n");
  }
  return out;
}

void require_same_run(const std::string& a, const std::string& b, int frames) {
  for (int f = 1; f <= frames; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "/frame_%04d.ply", f);
    INFO("frame " << f);
    REQUIRE(fs::exists(b + name));
    REQUIRE(read_text(a + name) == read_text(b + name));
    std::snprintf(name, sizeof name, "/frame_%04d.vtp", f);
    REQUIRE(read_text(a + name) == read_text(b + name));
  }
  // the collection lists every frame once, as the unbroken run's does
  CHECK(read_text(a + "/frames.pvd") == read_text(b + "/frames.pvd"));
  char last[32];
  std::snprintf(last, sizeof last, "\"frame_%04d.vtp\"", frames);
  CHECK(read_text(b + "/frames.pvd").find(last) != std::string::npos);
  CHECK_FALSE(fs::exists(b + "/frame_" + std::to_string(frames + 1) + ".ply"));
  CHECK(stats_without_time(a) == stats_without_time(b));
  CHECK(read_text(a + "/collider_poses.csv") == read_text(b + "/collider_poses.csv"));
  CHECK(read_text(a + "/colliders.csv") == read_text(b + "/colliders.csv"));
  CHECK(read_text(a + "/colliders.csv").size() > 100);  // the feedback was written
}

// The run of `scene` never stopped, on two threads, against the same run killed and resumed
// from its checkpoints, on one.
void check_resume(const std::string& name, const std::string& scene) {
  const std::string dir = temp_dir(name);
  const std::string graph = write_file(dir, "scene.json", scene);
  const std::string log = dir + "/log.txt";
  // the run that is never stopped, on two threads; the broken one runs on one
  REQUIRE(run_grains("run " + graph + " --out " + dir + "/a --quiet --threads 2", log) == 0);

  const std::string b = dir + "/b";
  // killed two frames past its second checkpoint (frame 8): frames 9 and 10 are made again
  const int written = run_and_kill({"run", graph, "--out", b, "--quiet", "--threads", "1",
                                     "--frames", "14", "--checkpoint-every", "4"},
                                    b, 10);
  REQUIRE(written >= 10);
  REQUIRE(written < 14);
  REQUIRE(run_grains("run --resume " + b + " --quiet --threads 1", log) == 0);
  // the run ended at frame 14 with a checkpoint there; --frames lengthens it to the graph's 18
  REQUIRE(run_grains("run --resume " + b + " --quiet --frames 18", log) == 0);
  require_same_run(dir + "/a", b, 18);
}

}  // namespace

TEST_CASE("a killed run resumed from its checkpoint writes the frames of an unbroken run",
          "[checkpoint][cli]") {
  check_resume("resume", kScene);
}

TEST_CASE("with the contacts one at a time, a resumed run carries the contacts' loads",
          "[checkpoint][cli][gauss_seidel]") {
  // contact_solver gauss_seidel carries each contact's load to the next substep: the checkpoint
  // keeps them, or the resumed run would start cold and differ (it did, with the loads dropped
  // on loading). The loads are repeated only where they balance an external force: the scene
  // gains gravity.
  std::string scene = kScene;
  auto replace = [&](const std::string& from, const std::string& to) {
    const size_t at = scene.find(from);
    REQUIRE(at != std::string::npos);
    scene.replace(at, from.size(), to);
  };
  replace("\"add_impact_data\": true", "\"add_impact_data\": true, \"contact_solver\": \"gauss_seidel\"");
  replace("\"inputs\": [\"pour\", \"pin\"]", "\"inputs\": [\"gravity\"]");
  replace("{\"name\": \"g\", \"type\": \"grains\"",
          "{\"name\": \"both\", \"type\": \"merge\", \"inputs\": [\"pour\", \"pin\"]},\n"
          "  {\"name\": \"gravity\", \"type\": \"force\", \"inputs\": [\"both\"], \"params\": "
          "{\"force\": [0, -9.81, 0], \"ignore_mass\": true}},\n"
          "  {\"name\": \"g\", \"type\": \"grains\"");
  check_resume("resume_gs", scene);
}

TEST_CASE("resume refuses what would not continue the same run", "[checkpoint][cli]") {
  const std::string dir = temp_dir("resume_refused");
  std::string scene = kScene;
  const std::string graph = write_file(dir, "scene.json", scene);
  const std::string log = dir + "/log.txt";
  const std::string out = dir + "/out";
  REQUIRE(run_grains("run " + graph + " --out " + out + " --quiet --frames 2 --checkpoint-every 1",
                     log) == 0);
  SECTION("no checkpoint") {
    REQUIRE(run_grains("run --resume " + dir, log) == 2);
    CHECK(read_text(log).find("no checkpoint there") != std::string::npos);
  }
  SECTION("a changed graph") {
    write_file(dir, "scene.json", scene + " ");
    REQUIRE(run_grains("run --resume " + out, log) == 2);
    CHECK(read_text(log).find("the graph has changed since the checkpoint") != std::string::npos);
  }
  SECTION("overrides") {
    REQUIRE(run_grains("run --resume " + out + " --set g.friction_with_particles=0.1", log) == 2);
    CHECK(read_text(log).find("--set cannot change it") != std::string::npos);
  }
  SECTION("fewer frames than it has made") {
    REQUIRE(run_grains("run --resume " + out + " --frames 1", log) == 2);
    CHECK(read_text(log).find("the checkpoint is at frame 2") != std::string::npos);
  }
  SECTION("a damaged checkpoint") {
    std::string bytes = read_text(out + "/checkpoint.grains");
    bytes[bytes.size() / 2] ^= 1;
    write_file(out, "checkpoint.grains", bytes);
    REQUIRE(run_grains("run --resume " + out, log) == 2);
    CHECK(read_text(log).find("damaged") != std::string::npos);
  }
  SECTION("--overwrite removes it with the frames") {
    REQUIRE(run_grains("run " + graph + " --out " + out + " --quiet --frames 1 --overwrite", log) == 0);
    CHECK_FALSE(fs::exists(out + "/checkpoint.grains"));
  }
}

namespace {

// A checkpoint's bytes (docs/output-format.md): its FNV-1a checksum, the last 8 bytes, made
// again over contents altered on purpose, as someone who meant to would
void reseal(std::string& bytes) {
  uint64_t h = 1469598103934665603ULL;
  for (size_t k = 0; k + 8 < bytes.size(); ++k) {
    h ^= static_cast<unsigned char>(bytes[k]);
    h *= 1099511628211ULL;
  }
  std::memcpy(&bytes[bytes.size() - 8], &h, 8);
}

uint64_t u64_at(const std::string& b, size_t at) {
  uint64_t v;
  std::memcpy(&v, b.data() + at, 8);
  return v;
}

// where the section `name` (a length-prefixed text) ends
size_t after_section(const std::string& b, const std::string& name) {
  std::string text(8, '\0');
  const uint64_t len = name.size();
  std::memcpy(&text[0], &len, 8);
  const size_t at = b.find(text + name);
  REQUIRE(at != std::string::npos);
  return at + 8 + name.size();
}

}  // namespace

TEST_CASE("resume refuses a checkpoint altered with its checksum made again",
          "[checkpoint][cli][hostile]") {
  // a connected sheet of grains (primitives) and loose grains on it (the grains node's rows)
  const std::string dir = temp_dir("resume_tampered");
  const std::string graph = write_file(dir, "sheet.json", R"JSON({"grains_graph": 1,
    "name": "tampered", "fps": 24, "frames": 4, "seed": 1, "nodes": [
    {"name": "sheet", "type": "source", "params": {"shape": "grid", "center": [0, 0.1, 0],
      "size": [0.1, 0, 0.1], "separation": 0.02, "connect_radius": 1.5}},
    {"name": "loose", "type": "source", "params": {"shape": "box", "center": [0, 0.13, 0],
      "size": [0.06, 0.04, 0.06], "separation": 0.02}},
    {"name": "g", "type": "grains", "inputs": ["sheet", "loose"]},
    {"name": "ground", "type": "collider", "params": {"shape": "plane"}},
    {"name": "s", "type": "solver", "inputs": ["g"], "params": {"colliders": ["ground"]}}],
    "output": {"dir": "unused"}})JSON");
  const std::string out = dir + "/out", log = dir + "/log.txt";
  const std::string set = "g.friction_with_particles=0.4";  // recorded: the resume applies it
  REQUIRE(run_grains("run " + graph + " --out " + out + " --set " + set +
                         " --quiet --frames 2 --checkpoint-every 1",
                     log) == 0);
  const std::string original = read_text(out + "/checkpoint.grains");
  REQUIRE(run_grains("run --resume " + out + " --quiet --frames 3", log) == 0);  // as written
  // the points: their count, next id, attributes (name, type, floats, ints), then primitives
  size_t at = after_section(original, "points");
  const uint64_t n = u64_at(original, at);
  REQUIRE(n > 36);
  const std::string points = std::to_string(n);
  at += 8 + 4;
  size_t pscale = 0;
  const uint64_t attributes = u64_at(original, at);
  at += 8;
  for (uint64_t a = 0; a < attributes; ++a) {
    const uint64_t len = u64_at(original, at);
    const std::string name = original.substr(at + 8, len);
    at += 8 + len + 4;
    if (name == "pscale") pscale = at + 8;  // its first float
    at += 8 + 4 * u64_at(original, at);
    at += 8 + 4 * u64_at(original, at);
  }
  const size_t prims = at;
  REQUIRE(pscale > 0);
  REQUIRE(u64_at(original, prims) > 0);
  // the grains node's rows: valid, skin, query scale, the cap, uniform; ids, radii, positions,
  // offsets, then the rows' entries
  at = after_section(original, "grains rows") + 1 + 4 + 4 + 4 + 1;
  at += 8 + 4 * u64_at(original, at);
  at += 8 + 4 * u64_at(original, at);
  at += 8 + 4 * u64_at(original, at);
  REQUIRE(u64_at(original, at) == n + 1);
  at += 8 + 4 * u64_at(original, at);
  REQUIRE(u64_at(original, at) > 0);
  const size_t entries = at + 8;

  struct Case {
    const char* what;
    size_t at;
    int32_t value;
    std::string message;
  };
  const float nan = std::numeric_limits<float>::quiet_NaN();
  int32_t nan_bits;
  std::memcpy(&nan_bits, &nan, 4);
  for (const Case& c : {Case{"a primitive's point beyond the points", prims + 8 + 4, 1000,
                             "primitive 0: point 1000 is out of range (" + points + " points)"},
                        Case{"a primitive's point negative", prims + 8, -1,
                             "primitive 0: point -1 is out of range"},
                        Case{"a radius not a number", pscale, nan_bits,
                             "attribute 'pscale' of point 0 is not finite"},
                        Case{"a row's entry beyond the grains", entries, 1000000,
                             "the grains' neighbour rows: entry 1000000 of " + points}}) {
    INFO(c.what);
    std::string bytes = original;
    std::memcpy(&bytes[c.at], &c.value, 4);
    reseal(bytes);
    write_file(out, "checkpoint.grains", bytes);
    CHECK(run_grains("run --resume " + out + " --quiet --frames 3", log) == 2);
    CHECK(read_text(log).find(c.message) != std::string::npos);
  }
  // the run's record: a NUL byte in the graph's path cut every message that quoted it; an
  // override altered was blamed on the command line
  const size_t path = original.find("sheet.json"), recorded = original.find(set);
  REQUIRE(path != std::string::npos);
  REQUIRE(recorded != std::string::npos);
  for (const auto& [what, at, byte, message] :
       {std::tuple<const char*, size_t, char, std::string>{
            "a NUL byte in the graph's path", path + 2, '\0',
            "checkpoint.grains: its graph's path holds a NUL byte"},
        {"an override altered", recorded + 1, 'X',
         "checkpoint.grains: its recorded --set do not apply: --set: "
         "'gXfriction_with_particles=0.4' is not NODE.PARAM=VALUE"}}) {
    INFO(what);
    std::string bytes = original;
    bytes[at] = byte;
    reseal(bytes);
    write_file(out, "checkpoint.grains", bytes);
    CHECK(run_grains("run --resume " + out + " --quiet --frames 3", log) == 2);
    CHECK(read_text(log).find(message) != std::string::npos);
  }
}
