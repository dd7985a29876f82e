// `grains-lab features`: the cost of each grains-node feature. See lab/features.h and
// bench/README.md.
//
// Every row is one forked run of the same scene (lab/bench_run.h): the baseline as written, one
// run per feature with its `--set` overrides, and the baseline again last. Cost is the row's
// stepping time per frame over the first baseline's. The repeated baseline runs the identical
// simulation, so its cost ratio is the timing noise of the machine during the benchmark and its
// final positions must match the first baseline's exactly (`moved` 0).
#include "lab/features.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "cli/options.h"
#include "engine/graph.h"
#include "engine/simulation.h"

namespace fs = std::filesystem;

namespace grains {
namespace {

constexpr int kQuickFrames = 12;

// One row of features.csv.
struct FeatureRow {
  std::string feature;
  std::vector<std::string> sets;  // NODE.PARAM=VALUE; none for the baselines
  BenchRow run;                   // scene, setting, frames, points, timings, memory, penetration
  double cost_ratio = 0;          // s/frame over the first baseline's
  double moved_radii = 0;  // RMS final-position distance from the first baseline, / mean pscale
  size_t compared = 0;     // ids that distance is over
};

std::string join(const std::vector<std::string>& v, const char* sep) {
  std::string out;
  for (size_t k = 0; k < v.size(); ++k) out += (k ? sep : "") + v[k];
  return out;
}

// A CSV field, quoted when it holds a separator or a quote.
std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

std::vector<Override> overrides_of(const BenchFeature& f) {
  std::vector<Override> out;
  for (const auto& s : f.sets) out.push_back(parse_override(s));
  return out;
}

void write_features_csv(const std::vector<FeatureRow>& rows, const std::string& path) {
  using bench::fmt;
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot write");
  out << features_csv_header() << "\n";
  for (const auto& f : rows) {
    const BenchRow& r = f.run;
    out << f.feature << "," << csv_field(join(f.sets, " ")) << "," << r.scene << ","
        << r.setting.substeps << "," << r.setting.iterations << "," << r.frames << "," << r.points
        << "," << r.threads << "," << fmt("%.4f", r.wall_s) << "," << fmt("%.4f", r.step_s) << ","
        << fmt("%.6g", r.s_per_frame()) << "," << fmt("%.6g", r.pi_per_s()) << ","
        << fmt("%.4f", f.cost_ratio) << "," << fmt("%.2f", r.peak_mib) << ","
        << fmt("%.1f", r.bytes_per_grain) << "," << fmt("%.6g", r.max_penetration) << ","
        << fmt("%.6g", r.mean_penetration) << "," << fmt("%.6g", f.moved_radii) << "," << f.compared
        << "\n";
  }
  if (!out) throw std::runtime_error(path + ": write failed");
}

bool find_features_section(const std::string& md, size_t& begin, size_t& end) {
  return find_marked_section(md, kFeaturesBegin, kFeaturesEnd, begin, end);
}

std::string features_markdown(const std::vector<FeatureRow>& rows, const FeatureOptions& o,
                              const std::string& path, const bench::Machine& m, int threads) {
  using bench::fmt;
  const BenchRow& b = rows.front().run;
  std::ostringstream md;
  md << kFeaturesBegin << "\n"
     << "## Feature cost: " << b.scene << "\n\n"
     << "What each `grains` node feature costs when it is on, written by `grains-lab "
        "features` (see `bench/README.md`); only this section is rewritten by it. `"
     << path << "` as written (" << b.setting.substeps << " substeps x " << b.setting.iterations
     << " iterations, " << b.points << " grains at the final frame, " << b.frames
     << " frames) is the baseline; every other row changes only the parameters shown, exactly as "
        "`grains run --set` does. Regenerate with:\n\n"
     << "```\n"
     << o.command << "\n```\n\n"
     << bench::machine_markdown(m, threads);
  if (o.quick) md << "- **Quick mode** (`--quick`): at most 12 frames, not the full benchmark\n";
  if (o.repeat > 1)
    md << "- **Repeats** (`--repeat " << o.repeat << "`): every row ran " << o.repeat
       << " times, in rounds over all rows; its timings are the fastest run's\n";
  md << "\nColumns: *s/frame* is stepping time only; *particle-iter/s* is points x substeps x "
        "iterations per second of it; *cost* is s/frame over the baseline's (below 1: cheaper "
        "than the scene as written). The last row runs the baseline again: its cost is how much "
        "timings wandered during the benchmark, so differences that small are noise. *peak MiB* "
        "is the run's maximum resident memory (each row is its own process); *max pen* / *mean "
        "pen* are the overlap of touching pairs at the final frame as a fraction of the summed "
        "radii; *moved* is the RMS distance of the final positions from the baseline's, in grain "
        "radii: how much the feature changes the result, not an error. Features that need more "
        "than a parameter (explicit constraints, pins, rigid shape matching) are not in this "
        "table: explicit constraints are timed by the `sheet_100k` scene (constraint-iter/s "
        "beside max strain); pins and shape matching have no benchmark scene yet.\n\n"
     << "| feature | --set | s/frame | particle-iter/s | cost | peak MiB | max pen | mean pen | "
        "moved (radii) |\n"
     << "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n";
  for (const auto& f : rows) {
    const BenchRow& r = f.run;
    md << "| " << f.feature << " | ";
    for (size_t k = 0; k < f.sets.size(); ++k) md << (k ? " `" : "`") << f.sets[k] << "`";
    md << " | " << fmt("%.4g", r.s_per_frame()) << " | " << bench::si(r.pi_per_s()) << " | "
       << fmt("%.2f", f.cost_ratio) << " | " << fmt("%.1f", r.peak_mib) << " | "
       << fmt("%.3g", r.max_penetration) << " | " << fmt("%.3g", r.mean_penetration) << " | "
       << fmt("%.3g", f.moved_radii) << " |\n";
  }
  md << kFeaturesEnd << "\n";
  return md.str();
}

}  // namespace

const std::vector<BenchFeature>& bench_features() {
  // each turns one feature of the grains node (DESIGN §4) away from its default, which the bench
  // scenes keep: off ones on (their row is their cost), on ones off (their row is their saving).
  // The Jacobi path's own parameters come with contact_solver jacobi (set with the default
  // gauss_seidel, a graph is refused), beside that path alone.
  static const std::vector<BenchFeature> features = {
      {"contact_solver_jacobi", {"grains.contact_solver=jacobi"}},
      {"jacobi_accurate_friction_off", {"grains.contact_solver=jacobi", "grains.accurate_friction=0"}},
      {"friction_off", {"grains.friction_with_particles=0"}},
      {"internal_collisions_off", {"grains.internal_collisions_weight=0"}},
      {"clumping", {"grains.clumping_weight=1"}},
      {"mass_shock_global",
       {"grains.enable_mass_shock_scaling=1", "grains.mass_shock_method=global"}},
      {"mass_shock_local",
       {"grains.enable_mass_shock_scaling=1", "grains.mass_shock_method=local"}},
      {"jacobi_update_collisions_during_iterations",
       {"grains.contact_solver=jacobi", "grains.update_collisions_during_iterations=1"}},
      {"jacobi_update_neighbors_during_iterations",
       {"grains.contact_solver=jacobi", "grains.update_neighbors_during_iterations=1"}},
      {"final_collision_test_off", {"grains.final_collision_test=0"}},
      {"disable_constraint_averaging", {"grains.disable_constraint_averaging=1"}},
      {"add_impact_data", {"grains.add_impact_data=1"}},
      {"enable_collision_feedback", {"grains.enable_collision_feedback=1"}},
      {"over_relaxation_1.5", {"grains.over_relaxation=1.5"}},
      {"max_neighbors_16", {"grains.max_neighbors=16"}},
      {"jacobi_chebyshev_0.95", {"grains.contact_solver=jacobi", "grains.chebyshev_rho=0.95"}},
      {"jacobi_chebyshev_0.95_mass_shock_8",
       {"grains.contact_solver=jacobi", "grains.chebyshev_rho=0.95", "grains.enable_mass_shock_scaling=1",
        "grains.shock_scaling_power=8"}},
  };
  return features;
}

const char* features_csv_header() {
  return "feature,sets,scene,substeps,iterations,frames,points,threads,wall_s,step_s,s_per_frame,"
         "particle_iterations_per_s,cost_ratio,peak_mib,bytes_per_grain,max_penetration,"
         "mean_penetration,moved_radii,compared";
}

std::string splice_features_section(const std::string& md, const std::string& section) {
  size_t b = 0, e = 0;
  if (find_features_section(md, b, e)) return md.substr(0, b) + section + md.substr(e);
  if (md.empty()) return section;
  std::string out = md;
  while (!out.empty() && out.back() == '\n') out.pop_back();
  return out + "\n\n" + section;
}

int run_feature_bench(const FeatureOptions& o) {
  // check the scene, the selection and every override before anything runs
  if (o.scenes.size() > 1)
    throw LoadError(
        "features", "",
        "measures one scene, got " + std::to_string(o.scenes.size()) + " (bench/README.md)");
  const std::string path = o.scenes.empty() ? kFeaturesDefaultScene : o.scenes.front();
  Graph g = load_graph(path);
  bench::check_bench_scene(g, path);
  bench::scene_setting(g);  // constant substeps and iterations

  std::vector<BenchFeature> runs{{kFeatureBaseline, {}}};
  for (const auto& name : o.only)
    if (std::none_of(bench_features().begin(), bench_features().end(),
                     [&](const BenchFeature& f) { return f.name == name; })) {
      std::string names;
      for (const auto& f : bench_features()) names += (names.empty() ? "" : ", ") + f.name;
      throw LoadError("--only", "", "unknown feature '" + name + "'; one of: " + names);
    }
  for (const auto& f : bench_features())
    if (o.only.empty() || std::find(o.only.begin(), o.only.end(), f.name) != o.only.end())
      runs.push_back(f);
  runs.push_back({kFeatureBaselineAgain, {}});
  for (const auto& f : runs) load_graph(path, overrides_of(f));

  // frames: --frames, else the sweep file's, else the graph's; --quick caps them
  int frames = o.frames > 0 ? o.frames : load_bench_sweep(path).frames;
  if (frames <= 0) frames = g.frames;
  if (o.quick) frames = std::min(frames, kQuickFrames);
  int threads =
      o.threads > 0 ? o.threads : static_cast<int>(std::max(1L, sysconf(_SC_NPROCESSORS_ONLN)));
  fs::create_directories(o.out_dir);
  bench::Machine machine = bench::describe_machine();
  const std::string scene = g.name.empty() ? fs::path(path).stem().string() : g.name;

  std::vector<FeatureRow> rows;
  std::vector<bench::KeyedPos> base_pos;
  double base_pscale = 0, base_spf = 0;
  bool have_base = false;
  int failures = 0;
  std::vector<int> row_of(runs.size(), -1);  // each run's row, once it has run
  const size_t total = size_t(std::max(1, o.repeat)) * runs.size();
  for (size_t t = 0; t < total; ++t) {  // rounds over the runs
    const int round = static_cast<int>(t / runs.size());
    const size_t k = t % runs.size();
    const BenchFeature& f = runs[k];
    if (round > 0 && row_of[k] < 0) continue;  // failed in the first round
    FeatureRow row;
    row.feature = f.name;
    row.sets = f.sets;
    row.run.scene = scene;
    row.run.path = path;
    std::vector<bench::KeyedPos> pos;
    double pscale = 0;
    int rc = bench::run_child(path, overrides_of(f), f.name, frames, threads, o.out_dir, row.run,
                              pos, pscale);
    if (rc == 2) return 2;
    if (rc != 0) {
      ++failures;
      continue;
    }
    if (round > 0) {  // a repeat: keep the faster timings, then the costs are recomputed
      FeatureRow& kept = rows[row_of[k]];
      if (row.run.step_s < kept.run.step_s) {
        kept.run.step_s = row.run.step_s;
        kept.run.wall_s = row.run.wall_s;
      }
      spdlog::info("features {:<36} run {}: {:.4g} s/frame, fastest {:.4g}", f.name, round + 1,
                   row.run.s_per_frame(), kept.run.s_per_frame());
      continue;
    }
    row_of[k] = static_cast<int>(rows.size());
    if (k == 0) {
      have_base = true;
      base_pos = pos;
      base_pscale = pscale;
      base_spf = row.run.s_per_frame();
    }
    row.cost_ratio = have_base && base_spf > 0 ? row.run.s_per_frame() / base_spf : std::nan("");
    double rms = have_base ? bench::rms_difference(pos, base_pos, row.compared) : std::nan("");
    row.moved_radii = base_pscale > 0 ? rms / base_pscale : std::nan("");
    spdlog::info(
        "features {:<36} {} frames  {} points  {:.4g} s/frame  {} particle-iter/s  cost {:.2f}  "
        "{:.1f} MiB  max pen {:.3g}  mean pen {:.3g}",
        f.name, row.run.frames, row.run.points, row.run.s_per_frame(),
        bench::si(row.run.pi_per_s()), row.cost_ratio, row.run.peak_mib, row.run.max_penetration,
        row.run.mean_penetration);
    if (f.name == kFeatureBaselineAgain && row.moved_radii != 0)
      spdlog::warn(
          "features: warning: the repeated baseline ended {:.3g} grain radii from the first: "
          "the runs are not deterministic, so `moved` mixes in noise",
          row.moved_radii);
    rows.push_back(std::move(row));
  }

  if (have_base && o.repeat > 1) {  // costs from the fastest timings
    base_spf = rows.front().run.s_per_frame();
    for (auto& r : rows)
      r.cost_ratio = base_spf > 0 ? r.run.s_per_frame() / base_spf : std::nan("");
  }
  std::string csv = o.out_dir + "/features.csv";
  write_features_csv(rows, csv);
  if (!have_base) {
    spdlog::error("wrote {}; the baseline failed, so {} is left as it was", csv, o.md_path);
    return 1;
  }
  std::string old;
  if (fs::exists(o.md_path)) {
    std::ifstream in(o.md_path);
    std::ostringstream ss;
    ss << in.rdbuf();
    old = ss.str();
  }
  // written aside and renamed: the rest of the report must survive a failed write
  fs::path mdp(o.md_path);
  if (mdp.has_parent_path()) fs::create_directories(mdp.parent_path());
  std::string tmp = o.md_path + ".part";
  {
    std::ofstream out(tmp);
    if (!out) throw std::runtime_error(tmp + ": cannot write");
    out << splice_features_section(old, features_markdown(rows, o, path, machine, threads));
    if (!out.flush()) throw std::runtime_error(tmp + ": write failed");
  }
  fs::rename(tmp, o.md_path);
  spdlog::info("wrote {} and the features section of {}", csv, o.md_path);
  return failures ? 1 : 0;
}

CLI::App* add_features_command(CLI::App& app, FeatureOptions& o, int argc, char** argv) {
  auto* f = app.add_subcommand(
      "features",
      "the cost of each grains feature on one scene as written; writes features.csv and the "
      "report's features section");
  f->add_option("scene", o.scenes, "one scene graph (default bench/settle_100k.json)");
  std::string names;
  for (const auto& b : bench_features()) names += (names.empty() ? "" : ", ") + b.name;
  f->add_option("--only", o.only, "only these features (comma-separated): " + names)
      ->delimiter(',');
  f->add_option("--out", o.out_dir, "output folder for features.csv (default out/bench)");
  f->add_option("--md", o.md_path,
                "Markdown report whose features section to rewrite (default "
                "BENCHMARKS.md)");
  f->add_flag("--quick", o.quick, "at most 12 frames");
  f->add_option("--frames", o.frames, "frames per run (default: the sweep file's or the graph's)")
      ->check(positive_number());
  f->add_option("--threads", o.threads, "worker threads (default: all cores)")
      ->check(CLI::Range(1, kMaxThreads));
  f->add_option("--repeat", o.repeat,
                "run every row this many times, in rounds; report the fastest timings (default 1)")
      ->check(positive_number());
  std::string cmd;
  for (int k = 0; k < argc; ++k) cmd += (k ? " " : "") + bench::quote_arg(argv[k]);
  o.command = cmd;
  return f;
}

}  // namespace grains
