// `grains bench`: speed versus error (DESIGN §5, §7). See app/bench.h and bench/README.md.
//
// Each (scene, setting) runs in a forked child so that its peak memory (ru_maxrss from wait4) is
// its own; the parent never runs OpenMP code, so forking is safe. The child writes one binary
// record (its figures) and the final positions keyed by id to a temporary file the parent reads.
#include "app/bench.h"
#include "app/bench_features.h"
#include "app/bench_run.h"
#include "app/options.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "engine/graph.h"
#include "engine/simulation.h"

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#include "stb_easy_font.h"
// Static, so it never clashes with another translation unit that defines the implementation.
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include "stb_image_write.h"
#pragma GCC diagnostic pop

namespace fs = std::filesystem;

namespace grains {
namespace bench {
namespace {

constexpr double kGravity = 9.81;  // energy: E = sum m |v|^2 / 2 + m g y

// ---------------------------------------------------------------------------------------------
// The child: one run of one setting

struct ChildRecord {
  int32_t magic = 0x62656e63;  // "benc"
  int32_t frames = 0;
  int32_t threads = 0;
  int32_t substeps = 0, iterations = 0;
  int32_t pad = 0;
  uint64_t points = 0;
  uint64_t n_final = 0;
  double wall_s = 0, step_s = 0, particle_iterations = 0, baseline_bytes = 0, mean_pscale = 0;
  double energy_initial = 0, energy_final = 0, constraint_iterations = 0;
  float max_penetration = 0, mean_penetration = 0, max_strain = 0, pad2 = 0;
};

double resident_bytes() {
  long pages_total = 0, pages_resident = 0;
  FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  if (std::fscanf(f, "%ld %ld", &pages_total, &pages_resident) != 2) pages_resident = 0;
  std::fclose(f);
  return static_cast<double>(pages_resident) * static_cast<double>(sysconf(_SC_PAGESIZE));
}

double total_energy(const Simulation& sim) {
  double e = 0;
  for (size_t k = 0; k < sim.object_count(); ++k) {
    const ParticleStore& pts = sim.object(k).pts;
    const float* P = pts.v3_if("P");
    const float* v = pts.v3_if("v");
    const float* m = pts.f_if("mass");
    for (size_t i = 0; i < pts.size(); ++i) {
      double mi = m ? m[i] : 1.0;
      double v2 = v ? double(v[3 * i]) * v[3 * i] + double(v[3 * i + 1]) * v[3 * i + 1] +
                          double(v[3 * i + 2]) * v[3 * i + 2]
                    : 0.0;
      e += mi * (0.5 * v2 + kGravity * (P ? P[3 * i + 1] : 0.0f));
    }
  }
  return e;
}

// A constant Int parameter of the node `node`, or its declared default.
int constant_int(const Graph& g, const std::string& node, const std::string& param) {
  int k = g.find(node);
  if (k < 0) throw LoadError(g.file, "/nodes", "no node named `" + node + "` (bench/README.md)");
  const NodeDesc& n = g.nodes[k];
  auto it = n.params.find(param);
  if (it != n.params.end()) {
    if (it->second.channels.size() != 1 ||
        it->second.channels[0].kind != ChannelSource::Kind::Constant)
      throw LoadError(g.file, n.pointer + "/params/" + param,
                      "the benchmark counts particle-iterations from a constant `" + param + "`");
    return static_cast<int>(std::lround(it->second.channels[0].value));
  }
  if (n.info)
    for (const ParamDecl& d : n.info->params)
      if (d.name == param) return static_cast<int>(std::lround(d.def[0]));
  throw LoadError(g.file, n.pointer, "node `" + node + "` has no parameter `" + param + "`");
}

void child_run(const std::string& path, const std::vector<Override>& overrides, int frames,
               int threads, const std::string& result_path) {
  auto t0 = std::chrono::steady_clock::now();
  Graph g = load_graph(path, overrides);
  if (frames > 0) g.frames = frames;
  const BenchSetting setting = scene_setting(g);
  ChildRecord rec;
  rec.substeps = setting.substeps;
  rec.iterations = setting.iterations;
  // The child inherits the parent's heap, whose free blocks (the earlier scenes' final positions,
  // read for the errors) are still resident: allocating into them copies pages that were
  // already counted, so the peak would miss them (sheet_100k after settle_1m: 596 B a grain
  // instead of about 800). Give them back before the baseline.
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
  rec.baseline_bytes = resident_bytes();
  rec.threads = threads;
  rec.frames = g.frames;
  Simulation sim(g, threads);
  for (int f = 1; f <= g.frames; ++f) {
    sim.step_frame();
    size_t points = 0, constraints = 0;
    for (size_t k = 0; k < sim.object_count(); ++k) {
      const SimObject& o = sim.object(k);
      rec.step_s += o.stats.wall_ms / 1000.0;
      rec.max_strain = std::max(rec.max_strain, o.stats.max_strain);
      points += o.pts.size();
      constraints += o.pts.prim_count();
    }
    rec.particle_iterations +=
        static_cast<double>(setting.substeps) * static_cast<double>(points) * setting.iterations;
    rec.constraint_iterations +=
        static_cast<double>(setting.substeps) * static_cast<double>(constraints) * setting.iterations;
    if (f == 1) rec.energy_initial = total_energy(sim);
  }
  rec.energy_final = total_energy(sim);

  std::vector<KeyedPos> out;
  double pscale_sum = 0, pen_weighted = 0;
  for (size_t k = 0; k < sim.object_count(); ++k) {
    const SimObject& o = sim.object(k);
    const ParticleStore& pts = o.pts;
    const float* P = pts.v3_if("P");
    const int32_t* id = pts.i_if("id");
    const float* r = pts.f_if("pscale");
    for (size_t i = 0; i < pts.size(); ++i) {
      int64_t key = (static_cast<int64_t>(k) << 32) | static_cast<uint32_t>(id ? id[i] : int32_t(i));
      out.push_back({key, P[3 * i], P[3 * i + 1], P[3 * i + 2]});
      pscale_sum += r ? r[i] : 0.0f;
    }
    rec.max_penetration = std::max(rec.max_penetration, o.stats.max_penetration);
    pen_weighted += double(o.stats.mean_penetration) * double(pts.size());
  }
  rec.points = out.size();
  rec.n_final = out.size();
  rec.mean_pscale = out.empty() ? 0 : pscale_sum / double(out.size());
  rec.mean_penetration = out.empty() ? 0.0f : static_cast<float>(pen_weighted / double(out.size()));
  rec.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::string tmp = result_path + ".part";
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw std::runtime_error(tmp + ": cannot write");
  bool ok = std::fwrite(&rec, sizeof rec, 1, f) == 1;
  if (!out.empty()) ok = ok && std::fwrite(out.data(), sizeof(KeyedPos), out.size(), f) == out.size();
  ok = (std::fclose(f) == 0) && ok;
  if (!ok) throw std::runtime_error(tmp + ": write failed");
  fs::rename(tmp, result_path);
}

}  // namespace

void check_bench_scene(const Graph& g, const std::string& path) {
  int solver = g.find("solver"), grains = g.find("grains");
  if (solver < 0 || g.nodes[solver].type != "solver")
    throw LoadError(path, "/nodes", "bench scenes need a solver node named `solver` (bench/README.md)");
  if (grains < 0 || g.nodes[grains].type != "grains")
    throw LoadError(path, "/nodes", "bench scenes need a grains node named `grains` (bench/README.md)");
}

BenchSetting scene_setting(const Graph& g) {
  return {constant_int(g, "solver", "substeps"), constant_int(g, "grains", "constraint_iterations")};
}

int run_child(const std::string& path, const std::vector<Override>& overrides,
              const std::string& label, int frames, int threads, const std::string& tmp_dir,
              BenchRow& row, std::vector<KeyedPos>& positions, double& mean_pscale) {
  static int counter = 0;
  std::string result_path =
      tmp_dir + "/.run_" + std::to_string(getpid()) + "_" + std::to_string(counter++) + ".bin";
  std::fflush(nullptr);
  pid_t pid = fork();
  if (pid < 0) throw std::runtime_error(std::string("fork failed: ") + std::strerror(errno));
  if (pid == 0) {
    int rc = 0;
    try {
      child_run(path, overrides, frames, threads, result_path);
    } catch (const LoadError& e) {
      std::fprintf(stderr, "grains bench: error: %s\n", e.what());
      rc = 2;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "grains bench: %s (%s) failed: %s\n", path.c_str(), label.c_str(),
                   e.what());
      rc = 1;
    }
    std::fflush(nullptr);
    _exit(rc);
  }
  int status = 0;
  struct rusage ru {};
  if (wait4(pid, &status, 0, &ru) < 0)
    throw std::runtime_error(std::string("wait4 failed: ") + std::strerror(errno));
  if (!WIFEXITED(status)) {
    std::fprintf(stderr, "grains bench: %s (%s): the run died (signal %d)\n", path.c_str(),
                 label.c_str(), WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    return 1;
  }
  if (WEXITSTATUS(status) != 0) return WEXITSTATUS(status);

  ChildRecord rec;
  FILE* f = std::fopen(result_path.c_str(), "rb");
  if (!f) throw std::runtime_error(result_path + ": missing result");
  bool ok = std::fread(&rec, sizeof rec, 1, f) == 1 && rec.magic == ChildRecord{}.magic;
  positions.resize(ok ? rec.n_final : 0);
  if (ok && rec.n_final)
    ok = std::fread(positions.data(), sizeof(KeyedPos), rec.n_final, f) == rec.n_final;
  std::fclose(f);
  fs::remove(result_path);
  if (!ok) throw std::runtime_error(result_path + ": unreadable result");
  std::sort(positions.begin(), positions.end(),
            [](const KeyedPos& a, const KeyedPos& b) { return a.key < b.key; });

  row.setting = {rec.substeps, rec.iterations};
  row.frames = rec.frames;
  row.points = rec.points;
  row.threads = rec.threads;
  row.wall_s = rec.wall_s;
  row.step_s = rec.step_s;
  row.particle_iterations = rec.particle_iterations;
  row.constraint_iterations = rec.constraint_iterations;
  double peak = static_cast<double>(ru.ru_maxrss) * 1024.0;  // Linux: KiB
  row.peak_mib = peak / (1024.0 * 1024.0);
  row.bytes_per_grain = rec.points ? std::max(0.0, peak - rec.baseline_bytes) / double(rec.points) : 0;
  row.max_penetration = rec.max_penetration;
  row.mean_penetration = rec.mean_penetration;
  row.max_strain = rec.max_strain;
  row.energy_initial = rec.energy_initial;
  row.energy_final = rec.energy_final;
  row.energy_drift = rec.energy_initial != 0
                         ? (rec.energy_final - rec.energy_initial) / std::fabs(rec.energy_initial)
                         : std::nan("");
  mean_pscale = rec.mean_pscale;
  return 0;
}

// RMS distance over the keys present in both (sorted) sets; sets `compared`.
double rms_difference(const std::vector<KeyedPos>& a, const std::vector<KeyedPos>& b, size_t& compared) {
  double sum = 0;
  compared = 0;
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (a[i].key < b[j].key) {
      ++i;
    } else if (b[j].key < a[i].key) {
      ++j;
    } else {
      double dx = double(a[i].x) - b[j].x, dy = double(a[i].y) - b[j].y, dz = double(a[i].z) - b[j].z;
      sum += dx * dx + dy * dy + dz * dz;
      ++compared;
      ++i;
      ++j;
    }
  }
  return compared ? std::sqrt(sum / double(compared)) : std::nan("");
}

// ---------------------------------------------------------------------------------------------
// The machine and the reports' number formats

Machine describe_machine() {
  Machine m;
  std::ifstream cpu("/proc/cpuinfo");
  for (std::string line; std::getline(cpu, line);)
    if (line.rfind("model name", 0) == 0) {
      auto c = line.find(':');
      if (c != std::string::npos) m.cpu = line.substr(line.find_first_not_of(" \t", c + 1));
      break;
    }
  m.cores = std::max(1L, sysconf(_SC_NPROCESSORS_ONLN));
  std::ifstream mem("/proc/meminfo");
  for (std::string line; std::getline(mem, line);)
    if (line.rfind("MemTotal:", 0) == 0) {
      m.mem_gib = std::atof(line.c_str() + 9) / (1024.0 * 1024.0);
      break;
    }
  std::ifstream la("/proc/loadavg");
  la >> m.load;
  std::time_t now = std::time(nullptr);
  char buf[64];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  m.date = buf;
  if (FILE* p = popen("git rev-parse --short HEAD 2>/dev/null", "r")) {
    char c[64] = {0};
    if (std::fgets(c, sizeof c, p)) m.commit = c;
    pclose(p);
    while (!m.commit.empty() && std::isspace(static_cast<unsigned char>(m.commit.back())))
      m.commit.pop_back();
  }
  // the sources the program is built from may differ from the commit
  m.dirty = !m.commit.empty() &&
            std::system("git diff --quiet HEAD -- engine nodes app CMakeLists.txt 2>/dev/null") != 0;
  return m;
}

std::string fmt(const char* f, double v) {
  if (!std::isfinite(v)) return "nan";
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string si(double v) {
  if (!std::isfinite(v)) return "nan";
  const char* unit[] = {"", " k", " M", " G"};
  int u = 0;
  while (std::fabs(v) >= 1000 && u < 3) {
    v /= 1000;
    ++u;
  }
  char buf[32];
  std::snprintf(buf, sizeof buf, v >= 100 ? "%.0f%s" : "%.3g%s", v, unit[u]);
  return buf;
}

std::string machine_markdown(const Machine& m, int threads) {
  std::ostringstream md;
  md << "- **Date:** " << m.date << "\n"
     << "- **Machine:** " << m.cpu << ", " << m.cores << " cores, "
     << fmt("%.1f", m.mem_gib) << " GiB memory; " << threads << " OpenMP threads"
     << (m.load.empty() ? "" : "; 1-minute load average " + m.load + " when it started")
     << "\n";
  if (!m.commit.empty())
    md << "- **Source:** commit `" << m.commit << "`"
       << (m.dirty ? " with uncommitted changes in engine/, nodes/ or app/" : "") << "\n";
  return md.str();
}

std::string quote_arg(const std::string& a) {
  if (!a.empty() && a.find_first_of(" \t\"'$\\*?;&|<>()") == std::string::npos) return a;
  std::string q = "'";
  for (char ch : a) q += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return q + "'";
}

}  // namespace bench

namespace {

using namespace bench;

constexpr int kQuickFrames = 12;

// ---------------------------------------------------------------------------------------------
// Sweeps

// An integer from 1 to 2^31 - 1 (a JSON integer past int would wrap in get<int>).
bool positive_int(const nlohmann::json& j) {
  if (j.is_number_unsigned()) return j.get<uint64_t>() >= 1 && j.get<uint64_t>() <= INT32_MAX;
  return j.is_number_integer() && j.get<int64_t>() >= 1 && j.get<int64_t>() <= INT32_MAX;
}

BenchSetting parse_setting(const nlohmann::json& j, const std::string& file, const std::string& ptr) {
  if (!j.is_array() || j.size() != 2 || !positive_int(j[0]) || !positive_int(j[1]))
    throw LoadError(file, ptr, "expected [substeps, iterations]: two integers from 1 to 2147483647");
  return BenchSetting{j[0].get<int>(), j[1].get<int>()};
}

std::vector<Override> setting_overrides(const BenchSetting& s) {
  // a sweep times fixed settings: error control would pick its own substeps
  return {Override{"solver", "substeps", std::to_string(s.substeps)},
          Override{"solver", "error_control", "0"},
          Override{"grains", "constraint_iterations", std::to_string(s.iterations)}};
}

std::string sweep_path_for(const std::string& graph_path) {
  fs::path p(graph_path);
  return (p.parent_path() / (p.stem().string() + ".sweep.json")).string();
}

// ---------------------------------------------------------------------------------------------
// The plot: seconds per frame (log) against error in grain radii (log), a curve per scene.

struct RGB {
  uint8_t r, g, b;
};

class Canvas {
 public:
  Canvas(int w, int h) : w_(w), h_(h), px_(size_t(w) * h * 3, 255) {}
  int w() const { return w_; }
  int h() const { return h_; }
  void set(int x, int y, RGB c) {
    if (x < 0 || y < 0 || x >= w_ || y >= h_) return;
    uint8_t* p = &px_[(size_t(y) * w_ + x) * 3];
    p[0] = c.r;
    p[1] = c.g;
    p[2] = c.b;
  }
  void rect(int x0, int y0, int x1, int y1, RGB c) {  // [x0,x1) x [y0,y1)
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) set(x, y, c);
  }
  void line(double x0, double y0, double x1, double y1, RGB c, int thick = 1) {
    int n = static_cast<int>(std::ceil(std::max(std::fabs(x1 - x0), std::fabs(y1 - y0)))) + 1;
    int lo = -(thick - 1) / 2, hi = thick / 2;
    for (int k = 0; k <= n; ++k) {
      double t = double(k) / n;
      int x = static_cast<int>(std::lround(x0 + (x1 - x0) * t));
      int y = static_cast<int>(std::lround(y0 + (y1 - y0) * t));
      for (int a = lo; a <= hi; ++a)
        for (int b = lo; b <= hi; ++b) set(x + a, y + b, c);
    }
  }
  void disc(double cx, double cy, double r, RGB c, bool filled = true) {
    for (int y = int(cy - r - 1); y <= int(cy + r + 1); ++y)
      for (int x = int(cx - r - 1); x <= int(cx + r + 1); ++x) {
        double d = std::hypot(x - cx, y - cy);
        if (filled ? d <= r : (d <= r && d >= r - 1.6)) set(x, y, c);
      }
  }
  // Text with stb_easy_font's segment glyphs, `scale` pixels per font unit. Returns the width.
  int text(int x, int y, const std::string& s, RGB c, int scale = 1, bool vertical = false) {
    std::vector<char> str(s.begin(), s.end());
    str.push_back('\0');
    std::vector<float> buf(16 * 1024);
    int quads = stb_easy_font_print(0, 0, str.data(), nullptr, buf.data(),
                                    static_cast<int>(buf.size() * sizeof(float)));
    int width = stb_easy_font_width(str.data()) * scale;
    for (int q = 0; q < quads; ++q) {
      const float* v = &buf[q * 16];  // 4 vertices of {x, y, z, rgba}
      float qx0 = v[0], qy0 = v[1], qx1 = v[0], qy1 = v[1];
      for (int k = 1; k < 4; ++k) {
        qx0 = std::min(qx0, v[4 * k]);
        qx1 = std::max(qx1, v[4 * k]);
        qy0 = std::min(qy0, v[4 * k + 1]);
        qy1 = std::max(qy1, v[4 * k + 1]);
      }
      for (int yy = int(qy0 * scale); yy < int(qy1 * scale); ++yy)
        for (int xx = int(qx0 * scale); xx < int(qx1 * scale); ++xx) {
          if (vertical)
            set(x + yy, y - xx, c);  // reads bottom to top
          else
            set(x + xx, y + yy, c);
        }
    }
    return width;
  }
  static int text_width(const std::string& s, int scale = 1) {
    std::vector<char> str(s.begin(), s.end());
    str.push_back('\0');
    return stb_easy_font_width(str.data()) * scale;
  }
  bool write_png(const std::string& path) const {
    return stbi_write_png(path.c_str(), w_, h_, 3, px_.data(), w_ * 3) != 0;
  }

 private:
  int w_, h_;
  std::vector<uint8_t> px_;
};

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

const RGB kPalette[] = {{31, 119, 180}, {214, 39, 40},  {44, 160, 44},  {255, 127, 14},
                        {148, 103, 189}, {140, 86, 75}, {227, 119, 194}, {23, 190, 207}};

void write_pareto_png(const std::vector<std::vector<BenchRow>>& scenes, const std::string& path) {
  Canvas c(1120, 640);
  const int X0 = 100, X1 = 760, Y0 = 60, Y1 = 560;
  const RGB black{0, 0, 0}, grey{225, 225, 225}, dark{90, 90, 90};
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
    c.line(x, Y0, x, Y1, grey);
    c.line(x, Y1, x, Y1 + 6, black);
    std::string s = tick_label(t);
    c.text(x - Canvas::text_width(s, 2) / 2, Y1 + 12, s, black, 2);
  }
  for (double t : log_ticks(ry.lo, ry.hi)) {
    int y = int(std::lround(py(t)));
    c.line(X0, y, X1, y, grey);
    c.line(X0 - 6, y, X0, y, black);
    std::string s = tick_label(t);
    c.text(X0 - 10 - Canvas::text_width(s, 2), y - 6, s, black, 2);
  }
  c.line(X0, Y0, X1, Y0, black);
  c.line(X0, Y1, X1, Y1, black);
  c.line(X0, Y0, X0, Y1, black);
  c.line(X1, Y0, X1, Y1, black);
  std::string xl = "seconds per frame (stepping only, log)";
  c.text((X0 + X1) / 2 - Canvas::text_width(xl, 2) / 2, Y1 + 40, xl, black, 2);
  std::string yl = "RMS error vs reference, grain radii (log)";
  c.text(18, (Y0 + Y1) / 2 + Canvas::text_width(yl, 2) / 2, yl, black, 2, true);
  std::string title = "grains bench: speed vs error (lines join Pareto-optimal settings)";
  c.text(X0, 20, title, black, 2);

  // curves
  int legend_y = Y0 + 4;
  for (size_t s = 0; s < scenes.size(); ++s) {
    const auto& rows = scenes[s];
    if (rows.empty()) continue;
    RGB col = kPalette[s % (sizeof kPalette / sizeof kPalette[0])];
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
      c.line(px(front[k - 1]->s_per_frame()), py(front[k - 1]->error_radii),
             px(front[k]->s_per_frame()), py(front[k]->error_radii), col, 2);
    for (const BenchRow* r : pts) {
      bool opt = std::find(front.begin(), front.end(), r) != front.end();
      double x = px(r->s_per_frame()), y = py(r->error_radii);
      c.disc(x, y, 5, col, opt);
      std::string lab = std::to_string(r->setting.substeps) + "x" + std::to_string(r->setting.iterations);
      c.text(int(x) + 7, int(y) - 14, lab, dark, 1);
    }
    // the reference (error 0) sits on the bottom axis as a triangle
    for (const auto& r : rows)
      if (r.reference && r.s_per_frame() > 0) {
        double x = px(r.s_per_frame());
        for (int k = 0; k < 9; ++k) c.line(x - k * 0.6, Y1 - 2 - k, x + k * 0.6, Y1 - 2 - k, col);
        std::string lab = "ref " + std::to_string(r.setting.substeps) + "x" +
                          std::to_string(r.setting.iterations);
        c.text(int(x) + 7, Y1 - 14, lab, dark, 1);
      }
    c.rect(X1 + 20, legend_y + 2, X1 + 36, legend_y + 14, col);
    std::string name = rows.front().scene + " (" + std::to_string(rows.front().points) + ")";
    c.text(X1 + 42, legend_y, name, black, 2);
    legend_y += 26;
  }
  std::string note1 = "filled: Pareto-optimal";
  std::string note2 = "triangle: reference (error 0)";
  c.text(X1 + 20, legend_y + 10, note1, dark, 1);
  c.text(X1 + 20, legend_y + 24, note2, dark, 1);
  if (!c.write_png(path)) throw std::runtime_error(path + ": cannot write");
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
     << "Speed against error for the `grains` PBD solver (DESIGN §7), written by `grains bench`"
     << " (see `bench/README.md`). Regenerate with:\n\n"
     << "```\n" << o.command << "\n```\n\n"
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
  // the hand-written notes, and the features section that belongs to `grains bench
  // --features`: carried over unchanged
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

BenchSweep default_bench_sweep() {
  BenchSweep s;
  s.settings = {{1, 5}, {1, 10}, {2, 10}, {2, 20}, {4, 20}};
  s.reference = {8, 40};
  return s;
}

BenchSweep load_bench_sweep(const std::string& graph_path) {
  std::string path = sweep_path_for(graph_path);
  if (!fs::exists(path)) return default_bench_sweep();
  std::ifstream in(path);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw LoadError(path, "", std::string("not valid JSON: ") + e.what());
  }
  if (!j.is_object()) throw LoadError(path, "", "expected an object");
  BenchSweep s = default_bench_sweep();
  for (auto it = j.begin(); it != j.end(); ++it)
    if (it.key() != "settings" && it.key() != "reference" && it.key() != "frames")
      throw LoadError(path, "/" + it.key(), "unknown key (expected settings, reference, frames)");
  if (j.contains("settings")) {
    if (!j["settings"].is_array() || j["settings"].empty())
      throw LoadError(path, "/settings", "expected a non-empty array of [substeps, iterations]");
    s.settings.clear();
    for (size_t k = 0; k < j["settings"].size(); ++k)
      s.settings.push_back(parse_setting(j["settings"][k], path, "/settings/" + std::to_string(k)));
  }
  if (j.contains("reference")) s.reference = parse_setting(j["reference"], path, "/reference");
  if (j.contains("frames")) {
    if (!positive_int(j["frames"]))
      throw LoadError(path, "/frames", "expected an integer from 1 to 2147483647");
    s.frames = j["frames"].get<int>();
  }
  return s;
}

BenchSweep quick_bench_sweep(const BenchSweep& s) {
  BenchSweep q;
  for (size_t k = 0; k < s.settings.size() && k < 2; ++k) q.settings.push_back(s.settings[k]);
  q.reference = {std::max(1, s.reference.substeps / 2), std::max(1, s.reference.iterations / 2)};
  for (const auto& st : q.settings) {  // never cheaper than a setting it judges
    q.reference.substeps = std::max(q.reference.substeps, st.substeps);
    q.reference.iterations = std::max(q.reference.iterations, st.iterations);
  }
  q.frames = s.frames > 0 ? std::min(s.frames, kQuickFrames) : -kQuickFrames;  // < 0: min with the graph's
  return q;
}

const char* bench_csv_header() {
  return "scene,substeps,iterations,reference,frames,points,threads,wall_s,step_s,s_per_frame,"
         "particle_iterations_per_s,peak_mib,bytes_per_grain,error_radii,compared,max_penetration,"
         "mean_penetration,max_strain,energy_initial,energy_final,energy_drift,"
         "constraint_iterations_per_s";
}

int run_bench(const BenchOptions& o) {
  if (o.features) return run_feature_bench(o);
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
  int threads = o.threads > 0 ? o.threads : static_cast<int>(std::max(1L, sysconf(_SC_NPROCESSORS_ONLN)));
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
          std::fprintf(stderr, "bench: warning: %s (%s) ended elsewhere on run %d: the runs are "
                       "not deterministic\n", row.scene.c_str(), label.c_str(), round + 1);
        if (row.step_s < kept.step_s) {
          kept.step_s = row.step_s;
          kept.wall_s = row.wall_s;
        }
        std::fprintf(stderr, "bench %-16s %2d x %-3d%s run %d: %.4g s/frame, fastest %.4g\n",
                     row.scene.c_str(), st.substeps, st.iterations,
                     row.reference ? " ref" : "    ", round + 1, row.s_per_frame(),
                     kept.s_per_frame());
        continue;
      }
      row_of[q] = static_cast<int>(rows.size());
      if (row.reference) {
        ref_index = static_cast<int>(rows.size());
        ref_pscale = pscale;
      }
      std::fprintf(stderr,
                   "bench %-16s %2d x %-3d%s %d frames  %zu points  %.4g s/frame  %s particle-iter/s  "
                   "%.1f MiB  max pen %.3g\n",
                   row.scene.c_str(), st.substeps, st.iterations, row.reference ? " ref" : "    ",
                   row.frames, row.points, row.s_per_frame(), si(row.pi_per_s()).c_str(), row.peak_mib,
                   row.max_penetration);
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
      std::fprintf(stderr, "bench %-16s %2d x %-3d error %.4g grain radii\n", rows[k].scene.c_str(),
                   rows[k].setting.substeps, rows[k].setting.iterations, rows[k].error_radii);
    }
    all.push_back(std::move(rows));
  }

  std::string csv = o.out_dir + "/results.csv";
  std::string png = o.out_dir + "/pareto.png";
  write_csv(all, csv);
  write_pareto_png(all, png);
  write_markdown(all, o, machine, threads, o.md_path);
  std::fprintf(stderr, "wrote %s, %s and %s\n", csv.c_str(), png.c_str(), o.md_path.c_str());
  return failures ? 1 : 0;
}

CLI::App* add_bench_command(CLI::App& app, BenchOptions& o, int argc, char** argv) {
  auto* b = app.add_subcommand("bench", "speed versus error: run benchmark scenes at several settings");
  b->add_option("scenes", o.scenes, "scene graphs (default: every bench/*.json here)");
  b->add_option("--out", o.out_dir, "output folder for results.csv and pareto.png, or features.csv (default out/bench)");
  b->add_option("--md", o.md_path, "Markdown report to regenerate (default BENCHMARKS.md)");
  b->add_flag("--quick", o.quick, "a reduced sweep that runs in seconds (with --features: at most 12 frames)");
  b->add_option("--frames", o.frames, "frames per run (default: the sweep file's or the graph's)")
      ->check(positive_number());
  b->add_option("--threads", o.threads, "worker threads (default: all cores)")
      ->check(CLI::Range(1, kMaxThreads));
  b->add_option("--repeat", o.repeat,
                "run every setting this many times, in rounds; report the fastest timings "
                "(default 1)")
      ->check(positive_number());
  auto* features = b->add_flag(
      "--features", o.features,
      "instead of the sweep: the cost of each grains feature on one scene as written (default "
      "bench/settle_100k.json); writes features.csv and the report's features section");
  std::string names;
  for (const auto& f : bench_features()) names += (names.empty() ? "" : ", ") + f.name;
  b->add_option("--only", o.only, "with --features: only these features (comma-separated): " + names)
      ->delimiter(',')
      ->needs(features);
  std::string cmd;
  for (int k = 0; k < argc; ++k) cmd += (k ? " " : "") + quote_arg(argv[k]);
  o.command = cmd;
  return b;
}

}  // namespace grains
