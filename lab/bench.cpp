// `grains-lab bench`: speed versus error (DESIGN §5, §7). See lab/bench.h and bench/README.md.
// Each (scene, setting) is one forked run of lab/bench_run.h's child runner.
#include "lab/bench.h"

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
#include "viewer-offline/image.h"

namespace fs = std::filesystem;

namespace grains {
namespace {

using namespace bench;

constexpr int kQuickFrames = 12;

std::vector<Override> setting_overrides(const BenchSetting& s) {
  // a sweep times fixed settings: error control would pick its own substeps
  return {Override{"solver", "substeps", std::to_string(s.substeps)},
          Override{"solver", "error_control", "0"},
          Override{"grains", "constraint_iterations", std::to_string(s.iterations)}};
}

// ---------------------------------------------------------------------------------------------
// The plot: seconds per frame (log) against error in grain radii (log), a curve per scene.

std::string tick_label(double v) {
  int e = static_cast<int>(std::floor(std::log10(v) + 1e-9));
  int m = static_cast<int>(std::lround(v / std::pow(10.0, e)));
  if (m == 10) {
    m = 1;
    ++e;
  }
  char buf[32];
  if (e >= -3 && e <= 4)
    std::snprintf(buf, sizeof buf, "%g", v);
  else if (m == 1)
    std::snprintf(buf, sizeof buf, "1e%d", e);
  else
    std::snprintf(buf, sizeof buf, "%de%d", m, e);
  return buf;
}

// Decade ticks, with 2 and 5 as well when the range spans few decades.
std::vector<double> log_ticks(double lo, double hi) {  // lo, hi: log10 bounds
  std::vector<double> out;
  bool fine = hi - lo < 2.5;
  for (int d = int(std::floor(lo)); d <= int(std::ceil(hi)); ++d)
    for (int m : {1, 2, 3, 5}) {
      if (m != 1 && !fine) continue;
      if (m == 3 && hi - lo > 1.2) continue;
      double v = m * std::pow(10.0, d);
      double lv = std::log10(v);
      if (lv >= lo - 1e-9 && lv <= hi + 1e-9) out.push_back(v);
    }
  return out;
}

struct Range {
  double lo = 1e300, hi = -1e300;
  void add(double v) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  void pad() {  // in log10 units
    if (lo > hi) lo = -1, hi = 0;
    if (hi - lo < 0.3) {
      double c = 0.5 * (lo + hi);
      lo = c - 0.5;
      hi = c + 0.5;
    }
    double m = 0.08 * (hi - lo);
    lo -= m;
    hi += m;
  }
};

// a colour from 0-255 channels
viewer::Rgb rgb(int r, int g, int b) {
  return {r / 255.0f, g / 255.0f, b / 255.0f};
}

const viewer::Rgb kPalette[] = {rgb(31, 119, 180),  rgb(214, 39, 40),   rgb(44, 160, 44),
                                rgb(255, 127, 14),  rgb(148, 103, 189), rgb(140, 86, 75),
                                rgb(227, 119, 194), rgb(23, 190, 207)};

void write_pareto_png(const std::vector<std::vector<BenchRow>>& scenes, const std::string& path) {
  using viewer::draw_disc;
  using viewer::draw_line;
  using viewer::draw_text;
  using viewer::text_width;
  viewer::Image c(1120, 640);
  const viewer::Rgb black = rgb(0, 0, 0), grey = rgb(225, 225, 225), dark = rgb(90, 90, 90);
  c.fill_rect(0, 0, c.width, c.height, rgb(255, 255, 255));
  const int X0 = 100, X1 = 760, Y0 = 60, Y1 = 560;
  Range rx, ry;
  for (const auto& rows : scenes)
    for (const auto& r : rows) {
      if (r.s_per_frame() > 0) rx.add(std::log10(r.s_per_frame()));
      if (!r.reference && r.error_radii > 0 && std::isfinite(r.error_radii))
        ry.add(std::log10(r.error_radii));
    }
  rx.pad();
  ry.pad();
  auto px = [&](double v) { return X0 + (std::log10(v) - rx.lo) / (rx.hi - rx.lo) * (X1 - X0); };
  auto py = [&](double v) { return Y1 - (std::log10(v) - ry.lo) / (ry.hi - ry.lo) * (Y1 - Y0); };

  // grid, ticks, labels
  for (double t : log_ticks(rx.lo, rx.hi)) {
    int x = int(std::lround(px(t)));
    draw_line(c, x, Y0, x, Y1, grey);
    draw_line(c, x, Y1, x, Y1 + 6, black);
    std::string s = tick_label(t);
    draw_text(c, x - text_width(s, 2) / 2, Y1 + 12, s, black, 2);
  }
  for (double t : log_ticks(ry.lo, ry.hi)) {
    int y = int(std::lround(py(t)));
    draw_line(c, X0, y, X1, y, grey);
    draw_line(c, X0 - 6, y, X0, y, black);
    std::string s = tick_label(t);
    draw_text(c, X0 - 10 - text_width(s, 2), y - 6, s, black, 2);
  }
  draw_line(c, X0, Y0, X1, Y0, black);
  draw_line(c, X0, Y1, X1, Y1, black);
  draw_line(c, X0, Y0, X0, Y1, black);
  draw_line(c, X1, Y0, X1, Y1, black);
  std::string xl = "seconds per frame (stepping only, log)";
  draw_text(c, (X0 + X1) / 2 - text_width(xl, 2) / 2, Y1 + 40, xl, black, 2);
  std::string yl = "RMS error vs reference, grain radii (log)";
  viewer::draw_text_up(c, 18, (Y0 + Y1) / 2 + text_width(yl, 2) / 2, yl, black, 2);
  std::string title = "grains-lab bench: speed vs error (lines join Pareto-optimal settings)";
  draw_text(c, X0, 20, title, black, 2);

  // curves
  int legend_y = Y0 + 4;
  for (size_t s = 0; s < scenes.size(); ++s) {
    const auto& rows = scenes[s];
    if (rows.empty()) continue;
    const viewer::Rgb& col = kPalette[s % (sizeof kPalette / sizeof kPalette[0])];
    std::vector<const BenchRow*> pts;
    for (const auto& r : rows)
      if (!r.reference && r.error_radii > 0 && std::isfinite(r.error_radii) && r.s_per_frame() > 0)
        pts.push_back(&r);
    std::sort(pts.begin(), pts.end(), [](const BenchRow* a, const BenchRow* b) {
      return a->s_per_frame() < b->s_per_frame();
    });
    std::vector<const BenchRow*> front;
    double best = 1e300;
    for (const BenchRow* r : pts)
      if (r->error_radii < best) {
        front.push_back(r);
        best = r->error_radii;
      }
    for (size_t k = 1; k < front.size(); ++k)
      draw_line(c, px(front[k - 1]->s_per_frame()), py(front[k - 1]->error_radii),
                px(front[k]->s_per_frame()), py(front[k]->error_radii), col, 2);
    for (const BenchRow* r : pts) {
      bool opt = std::find(front.begin(), front.end(), r) != front.end();
      double x = px(r->s_per_frame()), y = py(r->error_radii);
      draw_disc(c, x, y, 5, col, opt);
      std::string lab =
          std::to_string(r->setting.substeps) + "x" + std::to_string(r->setting.iterations);
      draw_text(c, int(x) + 7, int(y) - 14, lab, dark, 1);
    }
    // the reference (error 0) sits on the bottom axis as a triangle
    for (const auto& r : rows)
      if (r.reference && r.s_per_frame() > 0) {
        double x = px(r.s_per_frame());
        for (int k = 0; k < 9; ++k)
          draw_line(c, x - k * 0.6, Y1 - 2 - k, x + k * 0.6, Y1 - 2 - k, col);
        std::string lab = "ref " + std::to_string(r.setting.substeps) + "x" +
                          std::to_string(r.setting.iterations);
        draw_text(c, int(x) + 7, Y1 - 14, lab, dark, 1);
      }
    c.fill_rect(X1 + 20, legend_y + 2, X1 + 36, legend_y + 14, col);
    std::string name = rows.front().scene + " (" + std::to_string(rows.front().points) + ")";
    draw_text(c, X1 + 42, legend_y, name, black, 2);
    legend_y += 26;
  }
  std::string note1 = "filled: Pareto-optimal";
  std::string note2 = "triangle: reference (error 0)";
  draw_text(c, X1 + 20, legend_y + 10, note1, dark, 1);
  draw_text(c, X1 + 20, legend_y + 24, note2, dark, 1);
  viewer::write_png(path, c);
}

// ---------------------------------------------------------------------------------------------
// CSV and Markdown

void write_csv(const std::vector<std::vector<BenchRow>>& scenes, const std::string& path) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot write");
  out << bench_csv_header() << "\n";
  for (const auto& rows : scenes)
    for (const auto& r : rows)
      out << r.scene << "," << r.setting.substeps << "," << r.setting.iterations << ","
          << (r.reference ? 1 : 0) << "," << r.frames << "," << r.points << "," << r.threads << ","
          << fmt("%.4f", r.wall_s) << "," << fmt("%.4f", r.step_s) << ","
          << fmt("%.6g", r.s_per_frame()) << "," << fmt("%.6g", r.pi_per_s()) << ","
          << fmt("%.2f", r.peak_mib) << "," << fmt("%.1f", r.bytes_per_grain) << ","
          << fmt("%.6g", r.error_radii) << "," << r.compared << ","
          << fmt("%.6g", r.max_penetration) << "," << fmt("%.6g", r.mean_penetration) << ","
          << fmt("%.6g", r.max_strain) << "," << fmt("%.8g", r.energy_initial) << ","
          << fmt("%.8g", r.energy_final) << "," << fmt("%.6g", r.energy_drift) << ","
          << fmt("%.6g", r.ci_per_s()) << "\n";
  if (!out) throw std::runtime_error(path + ": write failed");
}

void write_markdown(const std::vector<std::vector<BenchRow>>& scenes, const BenchOptions& o,
                    const Machine& m, int threads, const std::string& path) {
  std::ostringstream md;
  md << "# Benchmarks\n\n"
     << "Speed against error for the `grains` PBD solver (DESIGN §7), written by `grains-lab bench`"
     << " (see `bench/README.md`). Regenerate with:\n\n"
     << "```\n"
     << o.command << "\n```\n\n"
     << machine_markdown(m, threads);
  if (o.quick) md << "- **Quick mode** (`--quick`): a reduced sweep, not the full benchmark\n";
  if (o.repeat > 1)
    md << "- **Repeats** (`--repeat " << o.repeat << "`): every setting ran " << o.repeat
       << " times, in rounds over all settings; its timings are the fastest run's\n";
  md << "\nColumns: *s/frame* is stepping time only (no file output, no diagnostics); "
        "*particle-iter/s* is the sum over substeps of points x constraint iterations divided by "
        "that time; *peak MiB* is the run's maximum resident memory (each setting runs in its own "
        "process); *B/grain* is that peak minus the memory before the simulation was built, per "
        "grain; *error* is the RMS distance of the final positions from the reference run's, over "
        "ids present in both, in mean grain radii (`pscale`); *max pen* / *mean pen* are the "
        "overlap of touching pairs at the final frame as a fraction of the summed radii; *strain* "
        "is the largest constraint strain over the run; *energy drift* is (E_final - E_1) / |E_1| "
        "with E = sum m|v|^2/2 + m g y (g = 9.81, y up) and E_1 measured at the end of frame 1. "
        "*constraint-iter/s* is the sum over substeps of explicit constraints x iterations divided "
        "by the stepping time. The reference row (**ref**) has error 0 by definition. "
        "The plot `pareto.png` in the output folder draws s/frame against error.\n";
  // scaling: every scene's 2 x 20 run side by side (the setting the settling scenes share)
  {
    std::ostringstream rows_md;
    for (const auto& rows : scenes)
      for (const auto& r : rows)
        if (r.setting == BenchSetting{2, 20}) {
          rows_md << "| " << r.scene << " | " << r.points << " | " << fmt("%.4g", r.s_per_frame())
                  << " | " << si(r.pi_per_s()) << " | " << fmt("%.1f", r.peak_mib) << " | "
                  << fmt("%.0f", r.bytes_per_grain) << " | " << fmt("%.3g", r.mean_penetration)
                  << " |\n";
          break;
        }
    if (!rows_md.str().empty())
      md << "\n## Scaling at 2 x 20\n\n"
         << "Each scene's 2 substeps x 20 iterations row, from the tables below.\n\n"
         << "| scene | grains | s/frame | particle-iter/s | peak MiB | B/grain | mean pen |\n"
         << "| --- | ---: | ---: | ---: | ---: | ---: | ---: |\n"
         << rows_md.str();
  }
  for (const auto& rows : scenes) {
    if (rows.empty()) continue;
    const BenchRow& f = rows.front();
    md << "\n## " << f.scene << "\n\n"
       << "`" << f.path << "`: " << f.points << " grains at the final frame, " << f.frames
       << " frames.\n\n"
       << "| substeps x iterations | s/frame | particle-iter/s | wall s | peak MiB | B/grain | "
          "error (radii) | max pen | mean pen | strain | energy drift | constraint-iter/s |\n"
       << "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n";
    for (const auto& r : rows)
      md << "| " << r.setting.substeps << " x " << r.setting.iterations
         << (r.reference ? " **ref**" : "") << " | " << fmt("%.4g", r.s_per_frame()) << " | "
         << si(r.pi_per_s()) << " | " << fmt("%.2f", r.wall_s) << " | " << fmt("%.1f", r.peak_mib)
         << " | " << fmt("%.0f", r.bytes_per_grain) << " | " << fmt("%.3g", r.error_radii) << " | "
         << fmt("%.3g", r.max_penetration) << " | " << fmt("%.3g", r.mean_penetration) << " | "
         << fmt("%.3g", r.max_strain) << " | " << fmt("%+.3g", r.energy_drift) << " | "
         << si(r.ci_per_s()) << " |\n";
  }
  // the hand-written notes, and the features section that belongs to `grains-lab features`:
  // carried over unchanged
  if (fs::exists(path)) {
    std::ifstream in(path);
    std::ostringstream old;
    old << in.rdbuf();
    for (const std::string& section :
         {marked_section_of(old.str(), kNotesBegin, kNotesEnd), features_section_of(old.str())})
      if (!section.empty()) md << "\n" << section;
  }
  fs::path p(path);
  if (p.has_parent_path()) fs::create_directories(p.parent_path());
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot write");
  out << md.str();
  if (!out) throw std::runtime_error(path + ": write failed");
}

}  // namespace

// ---------------------------------------------------------------------------------------------

BenchSweep quick_bench_sweep(const BenchSweep& s) {
  BenchSweep q;
  for (size_t k = 0; k < s.settings.size() && k < 2; ++k) q.settings.push_back(s.settings[k]);
  q.reference = {std::max(1, s.reference.substeps / 2), std::max(1, s.reference.iterations / 2)};
  for (const auto& st : q.settings) {  // never cheaper than a setting it judges
    q.reference.substeps = std::max(q.reference.substeps, st.substeps);
    q.reference.iterations = std::max(q.reference.iterations, st.iterations);
  }
  q.frames =
      s.frames > 0 ? std::min(s.frames, kQuickFrames) : -kQuickFrames;  // < 0: min with the graph's
  return q;
}

const char* bench_csv_header() {
  return "scene,substeps,iterations,reference,frames,points,threads,wall_s,step_s,s_per_frame,"
         "particle_iterations_per_s,peak_mib,bytes_per_grain,error_radii,compared,max_penetration,"
         "mean_penetration,max_strain,energy_initial,energy_final,energy_drift,"
         "constraint_iterations_per_s";
}

int run_bench(const BenchOptions& o) {
  // scenes
  std::vector<std::string> paths = o.scenes;
  if (paths.empty()) {
    if (fs::is_directory("bench"))
      for (const auto& e : fs::directory_iterator("bench")) {
        std::string name = e.path().filename().string();
        if (e.path().extension() == ".json" && name.find(".sweep.json") == std::string::npos)
          paths.push_back(e.path().string());
      }
    std::sort(paths.begin(), paths.end());
    if (paths.empty())
      throw LoadError("bench", "", "no scenes: bench/*.json not found here; pass scene files");
  }
  // check every scene and sweep before anything runs
  std::vector<BenchSweep> sweeps;
  std::vector<std::string> names;
  for (const auto& p : paths) {
    Graph g = load_graph(p);
    check_bench_scene(g, p);
    load_graph(p, setting_overrides({1, 1}));  // the overrides apply
    BenchSweep s = load_bench_sweep(p);
    if (o.quick) s = quick_bench_sweep(s);
    if (s.frames < 0) s.frames = std::min(g.frames, -s.frames);
    if (s.frames == 0) s.frames = g.frames;
    if (o.frames > 0) s.frames = o.frames;
    sweeps.push_back(s);
    names.push_back(g.name.empty() ? fs::path(p).stem().string() : g.name);
  }
  int threads =
      o.threads > 0 ? o.threads : static_cast<int>(std::max(1L, sysconf(_SC_NPROCESSORS_ONLN)));
  fs::create_directories(o.out_dir);
  Machine machine = describe_machine();

  std::vector<std::vector<BenchRow>> all;
  int failures = 0;
  for (size_t s = 0; s < paths.size(); ++s) {
    const BenchSweep& sw = sweeps[s];
    std::vector<BenchSetting> order;
    for (const auto& st : sw.settings)
      if (std::find(order.begin(), order.end(), st) == order.end()) order.push_back(st);
    bool ref_listed = std::find(order.begin(), order.end(), sw.reference) != order.end();
    if (!ref_listed) order.push_back(sw.reference);

    std::vector<BenchRow> rows;
    std::vector<std::vector<KeyedPos>> finals;
    double ref_pscale = 0;
    int ref_index = -1;
    std::vector<int> row_of(order.size(), -1);  // each setting's row, once it has run
    const size_t runs = size_t(std::max(1, o.repeat)) * order.size();
    for (size_t run = 0; run < runs; ++run) {  // rounds over the settings
      const int round = static_cast<int>(run / order.size());
      const size_t q = run % order.size();
      const BenchSetting& st = order[q];
      if (round > 0 && row_of[q] < 0) continue;  // failed in the first round
      BenchRow row;
      row.scene = names[s];
      row.path = paths[s];
      row.reference = st == sw.reference;
      std::vector<KeyedPos> pos;
      double pscale = 0;
      std::string label = std::to_string(st.substeps) + "x" + std::to_string(st.iterations);
      int rc = run_child(paths[s], setting_overrides(st), label, sw.frames, threads, o.out_dir, row,
                         pos, pscale);
      if (rc != 0) {
        if (rc == 2) return 2;
        ++failures;
        continue;
      }
      if (round > 0) {  // a repeat: keep the faster timings
        BenchRow& kept = rows[row_of[q]];
        size_t compared = 0;
        if (rms_difference(pos, finals[row_of[q]], compared) != 0 || compared != pos.size())
          spdlog::warn(
              "bench: warning: {} ({}) ended elsewhere on run {}: the runs are not deterministic",
              row.scene, label, round + 1);
        if (row.step_s < kept.step_s) {
          kept.step_s = row.step_s;
          kept.wall_s = row.wall_s;
        }
        spdlog::info("bench {:<16} {:2} x {:<3}{} run {}: {:.4g} s/frame, fastest {:.4g}",
                     row.scene, st.substeps, st.iterations, row.reference ? " ref" : "    ",
                     round + 1, row.s_per_frame(), kept.s_per_frame());
        continue;
      }
      row_of[q] = static_cast<int>(rows.size());
      if (row.reference) {
        ref_index = static_cast<int>(rows.size());
        ref_pscale = pscale;
      }
      spdlog::info(
          "bench {:<16} {:2} x {:<3}{} {} frames  {} points  {:.4g} s/frame  {} particle-iter/s  "
          "{:.1f} MiB  max pen {:.3g}",
          row.scene, st.substeps, st.iterations, row.reference ? " ref" : "    ", row.frames,
          row.points, row.s_per_frame(), si(row.pi_per_s()), row.peak_mib, row.max_penetration);
      rows.push_back(row);
      finals.push_back(std::move(pos));
    }
    for (size_t k = 0; k < rows.size(); ++k) {
      if (ref_index < 0) {
        rows[k].error_radii = std::nan("");
        continue;
      }
      double rms = rms_difference(finals[k], finals[ref_index], rows[k].compared);
      rows[k].error_radii = ref_pscale > 0 ? rms / ref_pscale : std::nan("");
      spdlog::info("bench {:<16} {:2} x {:<3} error {:.4g} grain radii", rows[k].scene,
                   rows[k].setting.substeps, rows[k].setting.iterations, rows[k].error_radii);
    }
    all.push_back(std::move(rows));
  }

  std::string csv = o.out_dir + "/results.csv";
  std::string png = o.out_dir + "/pareto.png";
  write_csv(all, csv);
  write_pareto_png(all, png);
  write_markdown(all, o, machine, threads, o.md_path);
  spdlog::info("wrote {}, {} and {}", csv, png, o.md_path);
  return failures ? 1 : 0;
}

CLI::App* add_bench_command(CLI::App& app, BenchOptions& o, int argc, char** argv) {
  auto* b =
      app.add_subcommand("bench", "speed versus error: run benchmark scenes at several settings");
  b->add_option("scenes", o.scenes, "scene graphs (default: every bench/*.json here)");
  b->add_option("--out", o.out_dir,
                "output folder for results.csv and pareto.png (default out/bench)");
  b->add_option("--md", o.md_path, "Markdown report to regenerate (default BENCHMARKS.md)");
  b->add_flag("--quick", o.quick, "a reduced sweep that runs in seconds");
  b->add_option("--frames", o.frames, "frames per run (default: the sweep file's or the graph's)")
      ->check(positive_number());
  b->add_option("--threads", o.threads, "worker threads (default: all cores)")
      ->check(CLI::Range(1, kMaxThreads));
  b->add_option("--repeat", o.repeat,
                "run every setting this many times, in rounds; report the fastest timings "
                "(default 1)")
      ->check(positive_number());
  std::string cmd;
  for (int k = 0; k < argc; ++k) cmd += (k ? " " : "") + quote_arg(argv[k]);
  o.command = cmd;
  return b;
}

}  // namespace grains
