// `grains plot RUN`. See plot.h.
//
// The image is a title and a legend, then one chart per quantity stacked over a shared time
// axis: each chart a framed rectangle with a light grid at "nice" values (1, 2 or 5 times a power
// of ten), its quantity named above it, and a curve per solver drawn as 2-pixel lines between the
// frames' values. Values that are not finite break a curve. The time axis is labelled under the
// last chart only.
#include "viewer-offline/plot.h"

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include "cli/log.h"
#include "engine/graph.h"  // LoadError

namespace grains::viewer {

namespace fs = std::filesystem;

const std::vector<double>* StatsTable::column(const std::string& c) const {
  for (size_t k = 0; k < columns.size(); ++k)
    if (columns[k] == c) return &values[k];
  return nullptr;
}

namespace {

std::vector<std::string> split_commas(const std::string& line) {
  std::vector<std::string> out;
  std::string field;
  std::istringstream in(line);
  while (std::getline(in, field, ',')) out.push_back(field);
  if (!line.empty() && line.back() == ',') out.push_back("");
  return out;
}

}  // namespace

StatsTable read_stats(const std::string& path, const std::string& name) {
  std::ifstream in(path);
  if (!in) throw LoadError(path, "", "cannot read it (a run's folder holds stats.csv)");
  StatsTable t;
  t.name = name;
  std::string line;
  if (!std::getline(in, line)) throw LoadError(path, "", "empty: not a stats.csv");
  if (!line.empty() && line.back() == '\r') line.pop_back();
  t.columns = split_commas(line);
  t.values.assign(t.columns.size(), {});
  if (!t.column("frame") || !t.column("time"))
    throw LoadError(path, "", "line 1: not a stats.csv (its header has no frame and time)");
  for (int number = 2; std::getline(in, line); ++number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    const std::vector<std::string> fields = split_commas(line);
    if (fields.size() != t.columns.size())
      throw LoadError(path, "", "line " + std::to_string(number) + ": " +
                                    std::to_string(fields.size()) + " fields, the header has " +
                                    std::to_string(t.columns.size()));
    for (size_t k = 0; k < fields.size(); ++k) {
      const char* s = fields[k].c_str();
      char* end = nullptr;
      const double v = std::strtod(s, &end);
      if (fields[k].empty() || *end != '\0')
        throw LoadError(path, "", "line " + std::to_string(number) + ": " + t.columns[k] + " '" +
                                      fields[k] + "' is not a number");
      t.values[k].push_back(v);
    }
  }
  if (t.rows() == 0) throw LoadError(path, "", "no frames yet (only the header)");
  return t;
}

namespace {

Rgb rgb(int r, int g, int b) { return {r / 255.0f, g / 255.0f, b / 255.0f}; }

const Rgb kPalette[] = {rgb(31, 119, 180), rgb(214, 39, 40),   rgb(44, 160, 44),
                        rgb(255, 127, 14), rgb(148, 103, 189), rgb(140, 86, 75),
                        rgb(227, 119, 194), rgb(23, 190, 207)};
const Rgb kBlack = rgb(30, 30, 30), kGrey = rgb(225, 225, 225), kDark = rgb(100, 100, 100);

Rgb curve_color(size_t k) { return kPalette[k % (sizeof kPalette / sizeof kPalette[0])]; }

// The step of about `count` ticks over span: 1, 2 or 5 times a power of ten.
double nice_step(double span, int count) {
  const double raw = span / count;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (m * mag >= raw * (1 - 1e-9)) return m * mag;
  return 10 * mag;
}

std::string tick_text(double v, double step) {
  if (std::fabs(v) < step * 1e-6) v = 0;
  char buf[32];
  const double a = std::fabs(v);
  if (a != 0 && (a >= 1e5 || a < 1e-3))
    std::snprintf(buf, sizeof buf, "%.3g", v);
  else
    std::snprintf(buf, sizeof buf, "%.*f", std::max(0, int(-std::floor(std::log10(step)))), v);
  return buf;
}

// One quantity's chart: its title and the columns it draws (the first solid, the second, if any,
// lighter and thinner).
struct Chart {
  const char* title;
  std::vector<const char*> columns;
};

const std::vector<Chart>& charts() {
  static const std::vector<Chart> c = {
      {"kinetic energy (J)", {"kinetic_energy"}},
      {"penetration, max (dark) and mean (light), fraction of summed radii",
       {"max_penetration", "mean_penetration"}},
      {"substeps per frame", {"substeps"}},
      {"error control: largest substep error (mean overlap / summed radii)", {"error"}},
      {"largest constraint strain", {"max_strain"}},
  };
  return c;
}

struct Range {
  double lo = INFINITY, hi = -INFINITY;
  void add(double v) {
    if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  }
};

}  // namespace

Image plot_stats(const std::vector<StatsTable>& tables, const std::string& title, int width,
                 int height) {
  Image img(width, height);
  img.fill_rect(0, 0, width, height, rgb(255, 255, 255));
  const int s = width >= 900 ? 2 : 1;  // text scale
  const int th = text_height(s);
  const int left = 12 * 6 * s + 24, right = 40, top = 3 * th + 24, bottom = 2 * th + 36;
  draw_text(img, left, 12, title, kBlack, s);
  // the legend: one swatch per solver, when there are several
  if (tables.size() > 1) {
    int x = left;
    for (size_t k = 0; k < tables.size(); ++k) {
      img.fill_rect(x, 18 + th, x + 24, 18 + th + 4 * s, curve_color(k));
      draw_text(img, x + 30, 16 + th, tables[k].name, kBlack, s);
      x += 30 + text_width(tables[k].name, s) + 24;
    }
  }

  Range tr;
  for (const StatsTable& t : tables)
    for (double v : *t.column("time")) tr.add(v);
  if (!(tr.lo < tr.hi)) tr.lo = std::min(0.0, tr.lo), tr.hi = tr.lo + 1;
  tr.lo = std::min(tr.lo, 0.0);
  const double x_step = nice_step(tr.hi - tr.lo, 8);

  const int n = static_cast<int>(charts().size());
  const double panel = double(height - top - bottom) / n;
  const int x0 = left, x1 = width - right;
  auto px = [&](double t) { return x0 + (t - tr.lo) / (tr.hi - tr.lo) * (x1 - x0); };
  for (int c = 0; c < n; ++c) {
    const Chart& chart = charts()[c];
    const int y0 = int(top + c * panel + th + 10), y1 = int(top + (c + 1) * panel - 10);
    draw_text(img, x0, y0 - th - 6, chart.title, kBlack, s);
    Range yr;
    bool any = false;
    for (const StatsTable& t : tables)
      for (const char* col : chart.columns)
        if (const std::vector<double>* v = t.column(col)) {
          any = true;
          for (double x : *v) yr.add(x);
        }
    if (!(yr.lo <= yr.hi)) yr.lo = 0, yr.hi = 1;
    yr.lo = std::min(yr.lo, 0.0);
    if (!(yr.hi > yr.lo)) yr.hi = yr.lo + 1;
    yr.hi += 0.05 * (yr.hi - yr.lo);
    auto py = [&](double v) { return y1 - (v - yr.lo) / (yr.hi - yr.lo) * (y1 - y0); };
    // grid and ticks
    const double y_step = nice_step(yr.hi - yr.lo, 4);
    for (double v = std::ceil(yr.lo / y_step) * y_step; v <= yr.hi; v += y_step) {
      const double y = py(v);
      draw_line(img, x0, y, x1, y, kGrey);
      const std::string label = tick_text(v, y_step);
      draw_text(img, x0 - 8 - text_width(label, s), int(y) - th / 2, label, kDark, s);
    }
    for (double t = std::ceil(tr.lo / x_step) * x_step; t <= tr.hi + 1e-9 * x_step; t += x_step) {
      const double x = px(t);
      draw_line(img, x, y0, x, y1, kGrey);
      if (c + 1 == n) {
        const std::string label = tick_text(t, x_step);
        draw_line(img, x, y1, x, y1 + 5, kBlack);
        draw_text(img, int(x) - text_width(label, s) / 2, y1 + 10, label, kDark, s);
      }
    }
    draw_line(img, x0, y0, x1, y0, kBlack);
    draw_line(img, x0, y1, x1, y1, kBlack);
    draw_line(img, x0, y0, x0, y1, kBlack);
    draw_line(img, x1, y0, x1, y1, kBlack);
    if (!any) {
      const std::string none = "not in stats.csv";
      draw_text(img, (x0 + x1 - text_width(none, s)) / 2, (y0 + y1 - th) / 2, none, kDark, s);
      continue;
    }
    // the curves: later columns lighter and thinner
    for (size_t k = 0; k < tables.size(); ++k) {
      const std::vector<double>& time = *tables[k].column("time");
      for (size_t col = 0; col < chart.columns.size(); ++col) {
        const std::vector<double>* v = tables[k].column(chart.columns[col]);
        if (!v) continue;
        const Rgb color = col == 0 ? curve_color(k) : mix(curve_color(k), rgb(255, 255, 255), 0.5f);
        const int thick = col == 0 ? 2 : 1;
        for (size_t r = 0; r < v->size(); ++r) {
          const bool here = std::isfinite((*v)[r]) && std::isfinite(time[r]);
          if (!here) continue;
          const bool prev = r > 0 && std::isfinite((*v)[r - 1]) && std::isfinite(time[r - 1]);
          if (prev)
            draw_line(img, px(time[r - 1]), py((*v)[r - 1]), px(time[r]), py((*v)[r]), color,
                      thick);
          else if (r + 1 >= v->size() || !std::isfinite((*v)[r + 1]))
            draw_disc(img, px(time[r]), py((*v)[r]), 2.5, color);  // a lone value
        }
      }
    }
  }
  const std::string xl = "time (s)";
  draw_text(img, (x0 + x1 - text_width(xl, s)) / 2, height - th - 10, xl, kBlack, s);
  return img;
}

int plot_command(const PlotOptions& o) {
  set_log_level(o.quiet, o.verbose);
  std::error_code ec;
  if (!fs::is_directory(o.run, ec))
    throw LoadError(o.run, "", "not a folder (a run's output folder)");
  std::vector<StatsTable> tables;
  if (fs::exists(fs::path(o.run) / "stats.csv", ec)) {
    tables.push_back(read_stats((fs::path(o.run) / "stats.csv").string(), ""));
  } else {
    std::vector<fs::path> subs;
    for (const auto& e : fs::directory_iterator(o.run, ec))
      if (e.is_directory() && fs::exists(e.path() / "stats.csv", ec)) subs.push_back(e.path());
    std::sort(subs.begin(), subs.end());
    for (const fs::path& p : subs)
      tables.push_back(read_stats((p / "stats.csv").string(), p.filename().string()));
  }
  if (tables.empty())
    throw LoadError(o.run, "", "no stats.csv (nor sub-folders holding one): not a run's folder");
  static const std::regex re(R"((\d{1,5})[xX](\d{1,5}))");
  std::smatch m;
  if (!std::regex_match(o.size, m, re))
    throw LoadError("--size", "", "'" + o.size + "': expected WxH, e.g. 1200x1300");
  const int w = std::stoi(m[1]), h = std::stoi(m[2]);
  if (w < 320 || h < 320 || w > 8192 || h > 8192)
    throw LoadError("--size", "",
                    "'" + o.size + "': width and height must be 320 to 8192 pixels");
  size_t frames = 0;
  double seconds = 0;
  for (const StatsTable& t : tables) {
    frames = std::max(frames, t.rows());
    seconds = std::max(seconds, t.column("time")->back());
  }
  char title[512];
  std::snprintf(title, sizeof title, "%s: %zu frames, %g s", o.run.c_str(), frames, seconds);
  const std::string out = o.out.empty() ? (fs::path(o.run) / "stats.png").string() : o.out;
  write_png(out, plot_stats(tables, title, w, h));
  spdlog::info("wrote {}", out);
  return 0;
}

CLI::App* add_plot_subcommand(CLI::App& app, PlotOptions& o) {
  auto* p = app.add_subcommand(
      "plot", "draw a run's stats.csv over time as PNG charts: kinetic energy, penetration, "
              "substeps, error, constraint strain");
  p->add_option("run", o.run, "the run's output folder (stats.csv, or a sub-folder per solver)")
      ->required();
  p->add_option("--out", o.out, "the PNG to write (default RUN/stats.png)");
  p->add_option("--size", o.size, "image size WxH (default 1200x1300)");
  add_verbosity_flags(p, o.quiet, o.verbose);
  return p;
}

}  // namespace grains::viewer
