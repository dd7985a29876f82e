// What the sweep and the feature table share (lab/bench_run.h): the forked child that runs one
// setting, the sweep files, the machine description and the report's marked sections.
//
// Each run goes in a forked child so that its peak memory (ru_maxrss from wait4) is its own; the
// parent never runs OpenMP code, so forking is safe. The child writes one binary record (its
// figures) and the final positions keyed by id to a temporary file the parent reads.
#include "lab/bench_run.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "engine/simulation.h"
#include "lab/source.h"

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
  spdlog::debug("{}: {} frames at {} substeps x {} iterations, in a child process", path, g.frames,
                setting.substeps, setting.iterations);
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
    rec.constraint_iterations += static_cast<double>(setting.substeps) *
                                 static_cast<double>(constraints) * setting.iterations;
    if (f == 1) rec.energy_initial = total_energy(sim);
    for (size_t k = 0; k < sim.object_count(); ++k)
      spdlog::debug("  frame {} solver '{}': {}", f, sim.object(k).name,
                    frame_detail(sim.object(k).stats));
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
      int64_t key =
          (static_cast<int64_t>(k) << 32) | static_cast<uint32_t>(id ? id[i] : int32_t(i));
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
  if (!out.empty())
    ok = ok && std::fwrite(out.data(), sizeof(KeyedPos), out.size(), f) == out.size();
  ok = (std::fclose(f) == 0) && ok;
  if (!ok) throw std::runtime_error(tmp + ": write failed");
  fs::rename(tmp, result_path);
}

}  // namespace

void check_bench_scene(const Graph& g, const std::string& path) {
  int solver = g.find("solver"), grains = g.find("grains");
  if (solver < 0 || g.nodes[solver].type != "solver")
    throw LoadError(path, "/nodes",
                    "bench scenes need a solver node named `solver` (bench/README.md)");
  if (grains < 0 || g.nodes[grains].type != "grains")
    throw LoadError(path, "/nodes",
                    "bench scenes need a grains node named `grains` (bench/README.md)");
}

BenchSetting scene_setting(const Graph& g) {
  return {constant_int(g, "solver", "substeps"),
          constant_int(g, "grains", "constraint_iterations")};
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
      spdlog::error("grains-lab: error: {}", e.what());
      rc = 2;
    } catch (const std::exception& e) {
      spdlog::error("grains-lab: {} ({}) failed: {}", path, label, e.what());
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
    spdlog::error("grains-lab: {} ({}): the run died (signal {})", path, label,
                  WIFSIGNALED(status) ? WTERMSIG(status) : 0);
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
  row.bytes_per_grain =
      rec.points ? std::max(0.0, peak - rec.baseline_bytes) / double(rec.points) : 0;
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
double rms_difference(const std::vector<KeyedPos>& a, const std::vector<KeyedPos>& b,
                      size_t& compared) {
  double sum = 0;
  compared = 0;
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (a[i].key < b[j].key) {
      ++i;
    } else if (b[j].key < a[i].key) {
      ++j;
    } else {
      double dx = double(a[i].x) - b[j].x, dy = double(a[i].y) - b[j].y,
             dz = double(a[i].z) - b[j].z;
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
  m.commit = lab::source_commit().id;
  m.dirty = lab::source_commit().dirty;
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
     << "- **Machine:** " << m.cpu << ", " << m.cores << " cores, " << fmt("%.1f", m.mem_gib)
     << " GiB memory; " << threads << " OpenMP threads"
     << (m.load.empty() ? "" : "; 1-minute load average " + m.load + " when it started") << "\n";
  md << "- **Source:** commit `" << m.commit << "`"
     << (m.dirty ? ", built with uncommitted changes (lab/source.h)" : "") << "\n";
  return md.str();
}

std::string quote_arg(const std::string& a) {
  if (!a.empty() && a.find_first_of(" \t\"'$\\*?;&|<>()") == std::string::npos) return a;
  std::string q = "'";
  for (char ch : a) q += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return q + "'";
}

}  // namespace bench

// ---------------------------------------------------------------------------------------------
// Sweep files

namespace {

// An integer from 1 to 2^31 - 1 (a JSON integer past int would wrap in get<int>).
bool positive_int(const nlohmann::json& j) {
  if (j.is_number_unsigned()) return j.get<uint64_t>() >= 1 && j.get<uint64_t>() <= INT32_MAX;
  return j.is_number_integer() && j.get<int64_t>() >= 1 && j.get<int64_t>() <= INT32_MAX;
}

BenchSetting parse_setting(const nlohmann::json& j, const std::string& file,
                           const std::string& ptr) {
  if (!j.is_array() || j.size() != 2 || !positive_int(j[0]) || !positive_int(j[1]))
    throw LoadError(file, ptr,
                    "expected [substeps, iterations]: two integers from 1 to 2147483647");
  return BenchSetting{j[0].get<int>(), j[1].get<int>()};
}

std::string sweep_path_for(const std::string& graph_path) {
  fs::path p(graph_path);
  return (p.parent_path() / (p.stem().string() + ".sweep.json")).string();
}

}  // namespace

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

// ---------------------------------------------------------------------------------------------
// The report's marked sections

bool find_marked_section(const std::string& md, const char* begin_marker, const char* end_marker,
                         size_t& begin, size_t& end) {
  end = md.find(end_marker);
  if (end == std::string::npos) return false;
  begin = md.rfind(begin_marker, end);
  if (begin == std::string::npos) return false;
  end += std::string(end_marker).size();
  if (end < md.size() && md[end] == '\n') ++end;
  return true;
}

std::string marked_section_of(const std::string& md, const char* begin, const char* end) {
  size_t b = 0, e = 0;
  if (!find_marked_section(md, begin, end, b, e)) return "";
  std::string s = md.substr(b, e - b);
  if (s.back() != '\n') s += '\n';
  return s;
}

std::string features_section_of(const std::string& md) {
  return marked_section_of(md, kFeaturesBegin, kFeaturesEnd);
}

}  // namespace grains
