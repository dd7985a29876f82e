// The grains program (DESIGN §5). Exit codes: 0 success, 2 bad input, 1 failure while running.
#include "app/cli.h"

#include <omp.h>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>

#include "cli/log.h"
#include "cli/options.h"
#include "cli/program.h"
#include "engine/checkpoint.h"
#include "engine/collider_poses.h"
#include "engine/cook.h"
#include "engine/dem_measures.h"
#include "engine/frame_writer.h"
#include "engine/geometry_io.h"
#include "engine/graph.h"
#include "engine/schema.h"
#include "engine/simulation.h"
#include "nodes/common.h"
#include "nodes/grains/opencl/device.h"
#include "nodes/register.h"
#include "viewer-offline/plot.h"
#include "viewer-offline/render.h"

namespace grains {
namespace {


std::vector<Override> parse_overrides(const std::vector<std::string>& sets) {
  std::vector<Override> out;
  for (const auto& s : sets) out.push_back(parse_override(s));
  return out;
}

// "4.2 s", "3 min 05 s", "2 h 07 min": a duration as a person reads it.
std::string duration_text(double s) {
  if (s < 60) return fmt::format("{:.1f} s", s);
  const long whole = std::lround(s);
  if (whole < 3600) return fmt::format("{} min {:02} s", whole / 60, whole % 60);
  return fmt::format("{} h {:02} min", whole / 3600, whole % 3600 / 60);
}

// A run's progress, told once a frame (frame): the frame, the simulated time it ends at, the
// points, the time it has taken and an estimate of the time left (the mean time per frame so far,
// times the frames left):
// - on a terminal, at the default level: a bar redrawn in place. It is written to stderr
//   directly, not logged: spdlog ends every message with a newline, and the bar must stay on
//   one line to be redrawn with '\r'.
// - otherwise an info line, "frame 10/96  points 1500  t 0.417 s  12.3 ms  max_penetration
//   0.0012  elapsed 4.1 s  left 35.2 s", for the first frame, the last, and at most one every
//   kEvery seconds between them (a long run's log stays short); with --verbose, every frame.
class RunProgress {
 public:
  static constexpr double kEvery = 5;  // s between two lines, at the default level

  // frames: the run's last frame; first: the frame it starts at (after a checkpoint when resumed)
  RunProgress(int frames, double fps, bool tty, int first = 1)
      : frames_(frames), first_(first), fps_(fps), bar_(tty && !log_verbose()) {}

  void frame(int done, size_t points, double ms, float max_penetration) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const int made = done - first_ + 1;  // by this process
    const double left = made > 0 ? elapsed / made * (frames_ - done) : 0;
    if (bar_) {
      draw_bar(done, points, ms, elapsed, left);
      return;
    }
    if (!(done == first_ || done == frames_ || elapsed - said_at_ >= kEvery || log_verbose())) return;
    said_at_ = elapsed;
    spdlog::info(
        "frame {}/{}  points {}  t {:.4g} s  {:.1f} ms  max_penetration {:.4f}  elapsed {}  left {}",
        done, frames_, points, done / fps_, ms, max_penetration, duration_text(elapsed),
        duration_text(left));
  }

 private:
  void draw_bar(int done, size_t points, double ms, double elapsed, double left) const {
    const int width = 30;
    const int filled = frames_ > 0 ? done * width / frames_ : width;
    std::fprintf(stderr,
                 "\r[%.*s%*s] %d/%d frames  t %.4g s  %zu points  %.1f ms/frame  %s elapsed, %s "
                 "left   ",
                 filled, "##############################", width - filled, "", done, frames_,
                 done / fps_, points, ms, duration_text(elapsed).c_str(),
                 duration_text(left).c_str());
    if (done == frames_) std::fputc('\n', stderr);
    std::fflush(stderr);
  }

  int frames_, first_;
  double fps_;
  bool bar_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  double said_at_ = 0;  // elapsed s at the last line
};

// What a run writes in its folder: frames (.ply, .vtp), frames.pvd, stats.csv,
// collider_poses.csv, colliders.csv, the checkpoint, and their .tmp files while writing.
bool run_owns(const std::filesystem::path& p) {
  const std::string name = p.filename().string();
  const std::string stem =
      name.size() > 4 && name.ends_with(".tmp") ? name.substr(0, name.size() - 4) : name;
  return stem == "stats.csv" || stem == kColliderPosesFile || stem == kCheckpointFile ||
         stem == "colliders.csv" || stem == kVtkCollectionFile ||
         (stem.starts_with("frame_") && (stem.ends_with(".ply") || stem.ends_with(".vtp")));
}

LoadError used_folder(const std::string& dir, const std::string& what) {
  return LoadError(dir, "",
                   "the output folder is not empty (" + what +
                       "): pass --overwrite to replace its frames, or name another");
}

// A run's folders must be empty: frames left by an earlier, longer run would be read as this
// one's. With `overwrite`, what a run owns (run_owns) is removed first and the rest kept, unless
// one of those files is among `inputs` (a source reading an earlier frame): then nothing is.
void prepare_output(const std::vector<std::string>& dirs, bool overwrite,
                    const std::vector<std::string>& inputs = {}) {
  namespace fs = std::filesystem;
  for (const std::string& dir : dirs) {
    std::error_code ec;
    if (!fs::exists(dir, ec)) continue;
    if (!fs::is_directory(dir, ec)) throw LoadError(dir, "", "the output folder is a file");
    std::vector<fs::path> owned, other;
    for (const auto& e : fs::directory_iterator(dir, ec))
      (e.is_regular_file() && run_owns(e.path()) ? owned : other).push_back(e.path());
    if (ec) throw LoadError(dir, "", "cannot list the output folder (" + ec.message() + ")");
    if (owned.empty() && other.empty()) continue;
    if (!overwrite) {
      const fs::path first = !owned.empty() ? owned.front() : other.front();
      throw used_folder(dir, std::to_string(owned.size() + other.size()) + " entries, e.g. " +
                                 first.filename().string());
    }
    for (const fs::path& f : owned)
      for (const std::string& in : inputs)
        if (fs::equivalent(f, in, ec))
          throw LoadError(in, "",
                          "the graph reads this file, and --overwrite would remove it from "
                          "the output folder first: copy it elsewhere");
    for (const fs::path& f : owned)
      if (!fs::remove(f, ec) && ec)
        throw std::runtime_error(f.string() + ": cannot remove (" + ec.message() + ")");
  }
}

// The float precision of an object's positions: stated once at its first frame with points
// (info: not with --quiet), and a warning, always, the first time contacts are resolved no finer
// than kWarnResolution of the smallest radius (Simulation stops the run at kCoarsestResolution).
void say_precision(const SimObject& o, int& said) {
  const FrameStats& s = o.stats;
  if (said == 2 || s.min_radius <= 0) return;
  const bool coarse = s.resolution >= kWarnResolution * s.min_radius;
  if (!coarse && said == 1) return;
  const std::string where = fmt::format(
      "solver '{}', frame {}: points reach {:.4g} m from the origin, where positions are "
      "resolved to {:.3g} m, {:.3g} of the smallest grain radius {:.3g} m",
      o.name, s.frame, s.max_coordinate, s.resolution, s.resolution / s.min_radius, s.min_radius);
  if (coarse)
    spdlog::warn(
        "grains: warning: {}; contacts are solved no finer than that (within {:.4g} m they "
        "would be)",
        where, precise_reach(s.min_radius, kWarnResolution));
  else
    spdlog::info("precision: {}", where);
  said = coarse ? 2 : 1;
}

// What `grains run` was asked for on its command line.
struct RunRequest {
  std::string graph, out;
  bool graph_given = false;  // named on the command line (an empty name is refused by the loader)
  int frames = 0;  // 0: the graph's
  int threads = 0;
  std::vector<std::string> sets;
  bool quiet = false, overwrite = false;
  size_t max_points = kDefaultMaxPoints;
  bool max_points_given = false;
  int checkpoint_every = 0;  // frames between checkpoints (0: none)
  std::string resume;        // the folder of a run to continue
  bool opencl = false;       // --opencl: every grains node with use_opencl (may change on resume)
};

// A run to resume: the checkpoint of its folder, checked against what the command line adds
// (the run continues with the graph, overrides and budget it was started with; --frames may
// lengthen it, --threads and --checkpoint-every may change).
Checkpoint resumed_run(RunRequest& req) {
  Checkpoint ck(req.resume);
  const RunRecord& rec = ck.record();
  auto refuse = [&](const std::string& what) {
    throw LoadError(req.resume, "", what + ": a resumed run continues as it was started (" +
                                        rec.graph + ")");
  };
  namespace fs = std::filesystem;
  std::error_code ec;
  if (req.graph_given && fs::weakly_canonical(req.graph, ec) != fs::path(rec.graph))
    refuse("the checkpoint is of another graph than " + req.graph);
  if (!req.sets.empty()) refuse("--set cannot change it");
  if (!req.out.empty()) refuse("--out cannot move it");
  if (req.overwrite) refuse("--overwrite would remove what it continues");
  if (file_hash(rec.graph) != rec.graph_hash)
    throw LoadError(rec.graph, "",
                    "the graph has changed since the checkpoint in " + req.resume +
                        " was written; a resumed run needs the graph it was started with");
  req.graph = rec.graph;
  req.sets = rec.sets;
  req.out = req.resume;
  if (!req.max_points_given) req.max_points = rec.max_points;
  if (req.frames == 0) req.frames = rec.frames;
  if (req.frames < ck.frame())
    throw LoadError(req.resume, "",
                    "the checkpoint is at frame " + std::to_string(ck.frame()) +
                        ", past the " + std::to_string(req.frames) + " frames asked for");
  if (req.checkpoint_every == 0) req.checkpoint_every = rec.checkpoint_every;
  return ck;
}

int cmd_run(RunRequest req) {
  std::optional<Checkpoint> resume;
  if (!req.resume.empty()) resume.emplace(resumed_run(req));
  if (!req.graph_given && req.resume.empty())
    throw LoadError("grains run", "", "a graph is required: name a graph file, or --resume DIR");
  // a resumed run's overrides are the checkpoint's: one that no longer applies to the graph
  // (which is the same file) is the checkpoint's fault, and named so
  auto recorded = [&](const LoadError& e) {
    return StateError(resume->path(), "its recorded --set do not apply: " + std::string(e.what()));
  };
  std::vector<Override> overrides;
  try {
    overrides = parse_overrides(req.sets);
  } catch (const LoadError& e) {
    if (resume) throw recorded(e);
    throw;
  }
  if (req.opencl) overrides.push_back(Override{"", "use_opencl", "true", "grains"});
  Graph g;
  try {
    g = load_graph(req.graph, overrides);
  } catch (const LoadError& e) {
    if (!resume || req.sets.empty()) throw;
    std::vector<Override> none;
    if (req.opencl) none.push_back(Override{"", "use_opencl", "true", "grains"});
    load_graph(req.graph, none);  // the graph's own fault (a data file since removed): thrown here
    throw recorded(e);
  }
  if (req.frames > 0) g.frames = req.frames;
  spdlog::debug("graph {}: {} nodes, {} solvers, {} frames at {:g} fps", req.graph, g.nodes.size(),
                g.solvers.size(), g.frames, g.fps);
  const std::string out = req.out.empty() ? g.output.dir : req.out;
  const bool quiet = req.quiet;
  Simulation sim(g, req.threads);
  sim.set_max_points(req.max_points);
  std::vector<std::string> dirs;
  for (size_t k = 0; k < sim.object_count(); ++k)
    dirs.push_back(sim.object_count() == 1 ? out : out + "/" + sim.object(k).name);
  std::vector<std::unique_ptr<FrameSink>> sinks;
  int first = 1;
  if (resume) {
    resume->restore(sim);
    first = sim.frame() + 1;
    for (const std::string& dir : dirs)
      sinks.push_back(std::make_unique<FrameWriter>(
          FrameWriter::continuing(dir, g.output.attributes, sim.frame(),
                                  FrameFormats::from(g.output.formats))));
  } else {
    const std::string checkpoint = out + "/" + kCheckpointFile;
    // the solvers' folders inside `out` and its checkpoint are the run's own; anything else
    // there counts
    namespace fs = std::filesystem;
    std::error_code ec;
    if (sim.object_count() > 1 && fs::is_directory(out, ec) && !req.overwrite)
      for (const auto& e : fs::directory_iterator(out, ec))
        if (std::find(dirs.begin(), dirs.end(), (fs::path(out) / e.path().filename()).string()) ==
            dirs.end())
          throw used_folder(out, e.path().filename().string());
    std::vector<std::string> inputs;  // files the nodes read
    for (const NodeDesc& d : g.nodes)
      if (auto it = d.params.find("file"); it != d.params.end() && !it->second.text.empty())
        inputs.push_back(resolve_path(g.base_dir, it->second.text));
    prepare_output(dirs, req.overwrite, inputs);
    if (req.overwrite && sim.object_count() > 1) {
      fs::remove(checkpoint, ec);
      fs::remove(checkpoint + ".tmp", ec);
    }
    for (const std::string& dir : dirs)
      sinks.push_back(std::make_unique<FrameWriter>(dir, g.output.attributes, false,
                                                    FrameFormats::from(g.output.formats)));
  }
  RunRecord record;
  if (req.checkpoint_every > 0) {
    record.graph = std::filesystem::weakly_canonical(req.graph).string();
    record.graph_hash = file_hash(record.graph);
    record.sets = req.sets;
    record.frames = g.frames;
    record.checkpoint_every = req.checkpoint_every;
    record.max_points = req.max_points;
  }
  for (const std::string& dir : dirs) spdlog::debug("writing frames to {}", dir);
  bool tty = isatty(fileno(stderr)) && !quiet;
  RunProgress progress(g.frames, g.fps, tty, first);
  std::vector<int> precision_said(sim.object_count(), 0);  // 1: stated, 2: warned
  for (int f = first; f <= g.frames; ++f) {
    sim.step_frame();
    size_t points = 0;
    double ms = 0;
    for (size_t k = 0; k < sim.object_count(); ++k) {
      const SimObject& o = sim.object(k);
      say_precision(o, precision_said[k]);
      spdlog::debug("frame {} solver '{}': {}", f, o.name, frame_detail(o.stats));
      sinks[k]->write(frame_output(f, o, f % g.output.every == 0));
      points += o.pts.size();
      ms += o.stats.wall_ms;
    }
    // after the frame's files: a checkpoint never runs ahead of the frames it resumes after
    if (req.checkpoint_every > 0 && (f % req.checkpoint_every == 0 || f == g.frames))
      write_checkpoint(out, record, sim);
    progress.frame(f, points, ms, sim.object(0).stats.max_penetration);
  }
  spdlog::info("wrote {}", out);
  return 0;
}

// a bound as the user would write it (0.001, 1e+06), not std::to_string's fixed six decimals
std::string bound_text(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.15g", v);
  return buf;
}

void print_nodes(const std::string& only, bool markdown) {
  bool found = false;
  if (markdown && only.empty())
    std::cout << "# Node reference\n\n"
              << "Generated by `grains nodes --markdown` from the node types' parameter tables "
                 "(`make docs`); do not edit by hand. `grains schema` prints the same tables as "
                 "the JSON Schema of a graph (`docs/graph.schema.json`).\n\n";
  for (const NodeTypeInfo* t : node_types()) {
    if (!only.empty() && t->type != only) continue;
    found = true;
    if (markdown) {
      std::cout << "## " << t->type << "\n\n" << t->doc << "\n\n";
      if (t->params.empty()) {
        std::cout << "No parameters.\n\n";
        continue;
      }
      std::cout << "| parameter | type | default | range | units | scaled by | meaning |\n"
                << "| --- | --- | --- | --- | --- | --- | --- |\n";
      for (const auto& p : t->params) {
        std::string range;
        if (p.has_min) range += (p.min_exclusive ? "> " : ">= ") + bound_text(p.min);
        if (p.has_max) range += (range.empty() ? "" : ", ") + ("<= " + bound_text(p.max));
        if (p.type == ParamType::Menu) {
          for (size_t k = 0; k < p.menu.size(); ++k) range += (k ? " \\| " : "") + p.menu[k];
        }
        std::cout << "| `" << p.name << "` | " << param_type_name(p.type) << " | `"
                  << p.default_text() << "` | " << range << " | " << p.units << " | "
                  << (p.scale_attribute.empty() ? "" : "`" + p.scale_attribute + "`") << " | "
                  << p.doc << " |\n";
      }
      std::cout << "\n";
    } else {
      std::cout << t->type << ": " << t->doc << "\n";
      for (const auto& p : t->params) {
        std::cout << "  " << p.name << " (" << param_type_name(p.type) << ", default "
                  << p.default_text();
        if (!p.units.empty()) std::cout << ", " << p.units;
        if (!p.scale_attribute.empty()) std::cout << ", scaled by " << p.scale_attribute;
        std::cout << ")\n      " << p.doc << "\n";
        if (p.type == ParamType::Menu) {
          std::cout << "      one of:";
          for (auto& m : p.menu) std::cout << " " << m;
          std::cout << "\n";
        }
      }
      std::cout << "\n";
    }
  }
  if (!found) throw LoadError("nodes", "", "unknown node type '" + only + "'");
}

int cmd_cook(const std::string& type, const std::string& in, const std::vector<std::string>& sets,
             int substeps, int frames, bool has_ground, float ground_y, int threads,
             const std::string& out, bool overwrite) {
  ParticleStore pts = read_ply(in);
  prepare_output({out}, overwrite);
  std::vector<std::pair<std::string, std::string>> params;
  for (const auto& s : sets) {
    auto eq = s.find('=');
    if (eq == std::string::npos || eq == 0)
      throw LoadError(in, "--set", "'" + s + "' is not PARAM=VALUE");
    params.push_back({s.substr(0, eq), s.substr(eq + 1)});
  }
  CookOptions o;
  o.substeps = substeps;
  o.frames = frames;
  o.ground = has_ground;
  o.ground_y = ground_y;
  o.threads = threads;
  o.out_dir = out;
  o.source = "cook " + type;
  cook_node(type, params, pts, o);
  spdlog::info("cooked {} on {} points; wrote {}", type, pts.size(), out);
  return 0;
}

// `grains heap`: the angle of a heap (engine/dem_measures.h) in one frame.
int cmd_heap(const std::string& path, double d, double cx, double cz) {
  ParticleStore pts = read_ply(path);
  if (!(d > 0)) {
    const float* ps = pts.f_if("pscale");
    if (!ps || pts.size() == 0) throw LoadError(path, "", "no pscale attribute: give --d");
    std::vector<float> r(ps, ps + pts.size());
    std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
    d = 2.0 * r[r.size() / 2];
  }
  HeapAngle h = heap_angle(pts, d, cx, cz);
  std::printf(
      "%s: heap angle %.1f deg (sd %.1f over %d sectors), cone %.1f deg, peak %.3f m, "
      "foot radius %.3f m, %zu grains (d %.4g m)\n",
      path.c_str(), h.angle_deg, h.spread_deg, h.sectors, h.cone_deg, h.peak, h.foot_radius,
      h.grains, d);
  return 0;
}

// grains devices: every OpenCL platform and device, each device's build of the grains kernels;
// with a choice (--device P:D, else GRAINS_OPENCL_DEVICE), that device only. No platform, or a
// choice that is malformed or names no device: exit 2 with the reason; a device that fails the
// build: its compiler log, exit 1.
int cmd_devices(std::string choice_text) {
  std::string where = "--device";
  if (choice_text.empty()) {
    const char* env = std::getenv("GRAINS_OPENCL_DEVICE");
    if (env && *env) choice_text = env, where = "GRAINS_OPENCL_DEVICE";
  }
  opencl::DeviceChoice choice;
  std::string problem;
  if (!choice_text.empty() && !opencl::parse_device_choice(choice_text, &choice, &problem)) {
    spdlog::error("grains devices: {}: {}", where, problem);
    return kBadInput;
  }
  const std::vector<opencl::Platform> list = opencl::platforms(&problem);
  if (list.empty()) {
    spdlog::error("grains devices: {}", problem);
    return kBadInput;
  }
  if (!choice_text.empty()) {
    if (std::string bad = opencl::choice_problem(list, choice); !bad.empty()) {
      spdlog::error("grains devices: {}: {}", where, bad);
      return kBadInput;
    }
  }
  int failed = 0;
  for (size_t p = 0; p < list.size(); ++p) {
    if (!choice_text.empty() && p != choice.platform) continue;
    const opencl::Platform& pl = list[p];
    std::printf("platform %zu: %s (%s, %s)\n", p, pl.name.c_str(), pl.vendor.c_str(),
                pl.version.c_str());
    if (pl.devices.empty()) std::printf("  no devices\n");
    for (size_t d = 0; d < pl.devices.size(); ++d) {
      if (!choice_text.empty() && d != choice.device) continue;
      const opencl::Device& dv = pl.devices[d];
      std::printf("  device %zu: %s (%s, %u compute units, %.0f MiB, largest buffer %.0f MiB, %s, %s)\n",
                  d, dv.name.c_str(), dv.type.c_str(), dv.compute_units,
                  static_cast<double>(dv.global_memory) / (1024.0 * 1024.0),
                  static_cast<double>(dv.largest_buffer) / (1024.0 * 1024.0), dv.version.c_str(),
                  dv.c_version.c_str());
      const opencl::BuildResult b = opencl::build_kernels(p, d);
      if (b.ok) {
        std::printf("    grains kernels: built in %.2f s\n", b.seconds);
      } else {
        ++failed;
        std::printf("    grains kernels: build failed\n%s\n", b.log.c_str());
      }
    }
  }
  std::fflush(stdout);
  return failed ? 1 : 0;
}

}  // namespace

int cli_main(int argc, char** argv) {
  register_builtin_nodes();
  CLI::App app{
      "grains: runs JSON node graphs of particles; the grains node is a PBD granular solver"};
  app.require_subcommand(1);

  std::string graph_path, out, in, type, cook_out;
  int frames = 0, threads = 0, substeps = 1, cook_frames = 1;
  bool quiet = false, verbose = false, markdown = false, opencl = false, overwrite = false;
  float ground = 0;
  size_t max_points = kDefaultMaxPoints;
  std::vector<std::string> sets;

  auto* run = app.add_subcommand("run", "run a graph and write frames and stats.csv");
  RunRequest req;
  auto* graph_opt = run->add_option("graph", graph_path, "graph file (JSON); none with --resume");
  run->add_option("--out", out, "output folder (default: the graph's output.dir)");
  run->add_option("--frames", frames, "number of frames (default: the graph's)")
      ->check(positive_number());
  run->add_option("--threads", threads, "worker threads (default: all cores)")
      ->check(CLI::Range(1, kMaxThreads));
  run->add_flag("--opencl", opencl,
                "run every grains node on the OpenCL device: use_opencl on (GRAINS_OPENCL_DEVICE=P:D picks "
                "the device)");
  run->add_option("--set", sets, "NODE.PARAM=VALUE, overrides a parameter");
  add_verbosity_flags(run, quiet, verbose);
  auto* max_points_opt = run->add_option("--max-points", max_points,
                  "the most points the run may hold (default 20000000, about 12 GB)")
      ->check(positive_number());
  run->add_flag("--overwrite", overwrite,
                "replace the frames (.ply, .vtp, frames.pvd), stats.csv, collider_poses.csv, "
                "colliders.csv and checkpoint an earlier run left in the output folder");
  run->add_option("--checkpoint-every", req.checkpoint_every,
                  "write the run's state to OUT/checkpoint.grains every N frames and at the end")
      ->check(positive_number());
  run->add_option("--resume", req.resume,
                  "continue the run whose output folder this is from its checkpoint (frames "
                  "after it are made again, bit for bit)");

  auto* validate = app.add_subcommand("validate", "load and check a graph without running it");
  validate->add_option("graph", graph_path, "graph file (JSON)")->required();

  std::string only;
  auto* nodes = app.add_subcommand("nodes", "print node types and their parameters");
  nodes->add_option("type", only, "one node type");
  nodes->add_flag("--markdown", markdown, "print Markdown tables");

  auto* schema = app.add_subcommand("schema", "print the JSON Schema of a graph file");

  auto* cook = app.add_subcommand("cook", "run one node type on the points of a PLY file");
  cook->add_option("type", type, "node type")->required();
  cook->add_option("--in", in, "input points (PLY; edges become constraints)")->required();
  cook->add_option("--set", sets, "PARAM=VALUE");
  cook->add_option("--substeps", substeps, "substeps per frame")->check(positive_number());
  cook->add_option("--frames", cook_frames, "frames")->check(positive_number());
  auto* ground_opt = cook->add_option("--ground", ground, "add a ground plane at this height");
  cook->add_option("--threads", threads, "worker threads")->check(CLI::Range(1, kMaxThreads));
  cook->add_option("--out", cook_out, "output folder")->required();
  cook->add_flag("--overwrite", overwrite,
                 "replace the frames, stats.csv and collider_poses.csv an earlier cook left in "
                 "the output folder");
  add_verbosity_flags(cook, quiet, verbose);

  std::string heap_frame;
  double heap_d = 0, heap_cx = 0, heap_cz = 0;
  auto* heap = app.add_subcommand(
      "heap", "measure the angle of a heap in a frame, as the DEM reference does");
  heap->add_option("frame", heap_frame, "a frame (PLY) written by run")->required();
  heap->add_option("--d", heap_d, "grain diameter, m (default: twice the median pscale)")
      ->check(positive_number());
  heap->add_option("--cx", heap_cx, "x of the heap's axis (m)");
  heap->add_option("--cz", heap_cz, "z of the heap's axis (m)");

  viewer::RenderOptions render_opts;
  auto* render = viewer::add_render_subcommand(app, render_opts);
  viewer::PlotOptions plot_opts;
  auto* plot = viewer::add_plot_subcommand(app, plot_opts);
  auto* devices = app.add_subcommand(
      "devices", "list the OpenCL platforms and devices, and whether each builds the grains kernels");
  std::string device_choice;
  devices->add_option("--device", device_choice,
                      "PLATFORM:DEVICE: build on this device only (default: the environment "
                      "variable GRAINS_OPENCL_DEVICE, else every device)");

  if (const int rc = parse_command_line("grains", app, argc, argv); rc >= 0) return rc;

  // run and cook share the flags; render and plot have their own (they set the level themselves)
  set_log_level(quiet, verbose);
  return report_errors("grains", [&]() -> int {
    if (run->parsed()) {
      req.opencl = opencl;
      req.graph = graph_path;
      req.graph_given = graph_opt->count() > 0;
      req.out = out;
      req.frames = frames;
      req.threads = threads;
      req.sets = sets;
      req.quiet = quiet;
      req.overwrite = overwrite;
      req.max_points = max_points;
      req.max_points_given = max_points_opt->count() > 0;
      return cmd_run(std::move(req));
    }
    if (validate->parsed()) {
      Graph g = load_graph(graph_path);
      std::printf("%s: ok (%zu nodes, %zu solvers, %d frames at %g fps)\n", graph_path.c_str(),
                  g.nodes.size(), g.solvers.size(), g.frames, g.fps);
      return 0;
    }
    if (nodes->parsed()) {
      print_nodes(only, markdown);
      return 0;
    }
    if (schema->parsed()) {
      std::cout << graph_schema_text();
      return 0;
    }
    if (heap->parsed()) return cmd_heap(heap_frame, heap_d, heap_cx, heap_cz);
    if (devices->parsed()) return cmd_devices(device_choice);
    if (render->parsed()) return viewer::render_command(render_opts);
    if (plot->parsed()) return viewer::plot_command(plot_opts);
    if (cook->parsed())
      return cmd_cook(type, in, sets, substeps, cook_frames, ground_opt->count() > 0, ground,
                      threads, cook_out, overwrite);
    return 0;
  });
}

}  // namespace grains
