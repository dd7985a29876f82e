// `grains render DIR`: two passes over the written frames. The first reads every frame for the
// scene's bounds (the default camera) and the colour-by range, so that framing and colours stay
// the same from frame to frame; the second renders each frame to PNG, feeds the video and keeps
// the contact sheet's thumbnails.
#include <omp.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <regex>
#include <set>
#include <sstream>

#include "cli/log.h"
#include "cli/options.h"
#include "engine/collider_poses.h"
#include "engine/geometry_io.h"
#include "engine/graph.h"
#include "engine/simulation.h"  // kMaxThreads
#include "viewer-offline/render.h"

namespace grains::viewer {
namespace {

namespace fs = std::filesystem;
constexpr int kOk = 0, kRunFailure = 1, kBadInput = 2;

// Bad command-line values or input folder; the message says what.
struct BadInput : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// One written frame: its number and a file per particle object (empty when an object has none).
struct FrameFiles {
  int number = 0;
  std::vector<std::string> paths;
};

std::map<int, std::string> frames_in(const fs::path& dir) {
  static const std::regex name(R"(frame_(\d+)\.ply)");
  std::map<int, std::string> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    std::smatch m;
    std::string f = e.path().filename().string();
    if (!e.is_regular_file() || !std::regex_match(f, m, name)) continue;
    const std::string digits = m[1];
    if (digits.size() > 10 || std::stoll(digits) > std::numeric_limits<int>::max())
      throw BadInput(e.path().string() + ": the frame number is past 2147483647");
    out[std::stoi(digits)] = e.path().string();
  }
  return out;
}

// DIR/frame_*.ply, or one sub-folder per object (what `grains run` writes for several solvers).
std::vector<FrameFiles> scan_frames(const std::string& dir, std::vector<std::string>& objects) {
  if (!fs::is_directory(dir)) throw BadInput(dir + ": not a folder");
  std::vector<std::map<int, std::string>> per_object;
  auto top = frames_in(dir);
  if (!top.empty()) {
    objects = {""};
    per_object.push_back(top);
  } else {
    std::vector<fs::path> subs;
    for (const auto& e : fs::directory_iterator(dir))
      if (e.is_directory()) subs.push_back(e.path());
    std::sort(subs.begin(), subs.end());
    for (const auto& s : subs) {
      auto f = frames_in(s);
      if (f.empty()) continue;
      objects.push_back(s.filename().string());
      per_object.push_back(std::move(f));
    }
  }
  if (per_object.empty())
    throw BadInput(dir + ": no frame_NNNN.ply files (nor sub-folders holding them)");
  std::set<int> numbers;
  for (const auto& m : per_object)
    for (const auto& [k, v] : m) numbers.insert(k);
  std::vector<FrameFiles> frames;
  for (int k : numbers) {
    FrameFiles f;
    f.number = k;
    for (const auto& m : per_object) {
      auto it = m.find(k);
      f.paths.push_back(it == m.end() ? "" : it->second);
    }
    frames.push_back(std::move(f));
  }
  return frames;
}

void parse_size(const std::string& s, int& w, int& h) {
  static const std::regex re(R"((\d{1,5})[xX](\d{1,5}))");
  std::smatch m;
  if (!std::regex_match(s, m, re)) throw BadInput("--size '" + s + "': expected WxH, e.g. 960x540");
  w = std::stoi(m[1]);
  h = std::stoi(m[2]);
  if (w < 8 || h < 8 || w > 16384 || h > 16384)
    throw BadInput("--size '" + s + "': width and height must be 8 to 16384 pixels");
}

Camera parse_camera(const std::string& s, int w, int h) {
  std::vector<float> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      size_t used = 0;
      v.push_back(std::stof(item, &used));
      if (item.find_first_not_of(" \t", used) != std::string::npos || !std::isfinite(v.back()))
        throw std::invalid_argument(item);
    } catch (const std::exception&) {
      throw BadInput("--camera '" + s + "': '" + item + "' is not a finite number");
    }
  }
  if (v.size() != 7)
    throw BadInput("--camera '" + s + "': expected ex,ey,ez,tx,ty,tz,fov (7 numbers)");
  Vec3 eye{v[0], v[1], v[2]}, target{v[3], v[4], v[5]};
  if (length(target - eye) <= 0) throw BadInput("--camera '" + s + "': eye and target coincide");
  if (!(v[6] > 1 && v[6] < 179))
    throw BadInput("--camera '" + s + "': fov must be between 1 and 179 degrees");
  return Camera::look_at(eye, target, v[6], w, h);
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string find_on_path(const std::string& exe) {
  const char* path = std::getenv("PATH");
  if (!path) return "";
  std::stringstream ss(path);
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    if (dir.empty()) continue;
    std::string p = dir + "/" + exe;
    if (::access(p.c_str(), X_OK) == 0 && fs::is_regular_file(p)) return p;
  }
  return "";
}

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// The same collider in the same place: name, shape and pose alike, bit for bit.
bool same_collider(const ColliderState& a, const ColliderState& b) {
  const Shape &p = a.shape, &q = b.shape;
  bool same = a.name == b.name && p.kind == q.kind && p.size.x == q.size.x &&
              p.size.y == q.size.y && p.size.z == q.size.z && p.radius == q.radius &&
              p.tube == q.tube && p.height == q.height && a.pose.t.x == b.pose.t.x &&
              a.pose.t.y == b.pose.t.y && a.pose.t.z == b.pose.t.z && a.pose.s == b.pose.s;
  for (int k = 0; k < 9; ++k) same = same && a.pose.R[k] == b.pose.R[k];
  return same;
}

// The colliders as the run posed them (DIR/collider_poses.csv, one per object folder; written by
// engine/frame_writer.h), read instead of evaluating the graph again: an expression that uses
// the object's variables (OBJ, OBJID, NOBJ) is drawn where it was simulated.
struct RecordedColliders {
  std::vector<std::map<int, std::vector<ColliderState>>> objects;  // per object with a file
  std::vector<std::string> missing;  // object folders without a pose file
  std::vector<int> frames_without;   // rendered frames that a non-empty pose file lacks

  // Every object's colliders at `frame`, in object then file order; a collider that several
  // solvers share is drawn once where they posed it alike, and once per pose where its
  // expressions placed it differently for each (e.g. by $OBJID).
  std::vector<ColliderState> at(int frame) {
    std::vector<ColliderState> out;
    bool lacking = false;
    for (const auto& poses : objects) {
      if (poses.empty()) continue;  // a solver without colliders
      auto it = poses.find(frame);
      if (it == poses.end()) {
        lacking = true;
        continue;
      }
      for (const ColliderState& c : it->second) {
        bool seen = false;
        for (const ColliderState& o : out) seen = seen || same_collider(o, c);
        if (!seen) out.push_back(c);
      }
    }
    if (lacking) frames_without.push_back(frame);
    return out;
  }
};

// Reads the pose file of each object folder. A damaged file is bad input (GeometryError); a
// missing one is noted in `missing`.
RecordedColliders read_recorded_colliders(const std::string& dir,
                                          const std::vector<std::string>& objects) {
  RecordedColliders r;
  for (const std::string& o : objects) {
    const fs::path path = fs::path(dir) / o / kColliderPosesFile;
    std::error_code ec;
    if (!fs::exists(path, ec)) {
      r.missing.push_back(path.string());
      continue;
    }
    r.objects.push_back(read_collider_poses(path.string()));
  }
  return r;
}

// What the first pass learns from every frame.
struct Survey {
  Bounds bounds;  // grains (P +- pscale) over all frames
  float vmin = std::numeric_limits<float>::infinity(),
        vmax = -std::numeric_limits<float>::infinity();
  bool found = false;  // the colour-by attribute exists somewhere
  size_t max_points = 0;
  std::string first_file;
  std::vector<std::string> point_attribs, edge_attribs;  // of the first frame, for messages
};

// The grains' box for framing: P +- pscale, except that with many grains a stray few (0.1% on
// each side of each axis) do not count, so one grain flung far away does not shrink the picture.
Bounds framing_bounds(const ParticleStore& o) {
  Bounds b;
  const float* P = o.v3_if("P");
  const float* ps = o.f_if("pscale");
  const size_t n = o.size();
  if (n < 1000) {
    for (size_t i = 0; i < n; ++i) b.add(load3(P, i), ps ? ps[i] : 0);
    return b;
  }
  float rmax = 0;
  for (size_t i = 0; ps && i < n; ++i)
    if (std::isfinite(ps[i])) rmax = std::max(rmax, ps[i]);
  const size_t cut = n / 1000;
  std::vector<float> v;
  Vec3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    v.clear();
    for (size_t i = 0; i < n; ++i)
      if (std::isfinite(P[3 * i + a])) v.push_back(P[3 * i + a]);
    if (v.size() <= 2 * cut) return b;
    std::nth_element(v.begin(), v.begin() + cut, v.end());
    lo[a] = v[cut] - rmax;
    std::nth_element(v.begin(), v.end() - 1 - cut, v.end());
    hi[a] = v[v.size() - 1 - cut] + rmax;
  }
  b.add(lo);
  b.add(hi);
  return b;
}

std::vector<ParticleStore> read_objects(const FrameFiles& f) {
  std::vector<ParticleStore> out;
  for (const auto& p : f.paths)
    if (!p.empty()) out.push_back(read_ply(p));
  return out;
}

Survey survey(const std::vector<FrameFiles>& frames, const std::string& color_by) {
  Survey s;
  s.first_file = frames.front().paths.front();
  for (const auto& p : frames.front().paths)
    if (!p.empty()) {
      s.first_file = p;
      break;
    }
  std::string error;
  const int64_t n = static_cast<int64_t>(frames.size());
#pragma omp parallel
  {
    Survey mine;
    std::vector<float> values;
#pragma omp for schedule(dynamic)
    for (int64_t k = 0; k < n; ++k) {
      std::vector<ParticleStore> objs;
      try {
        objs = read_objects(frames[k]);
      } catch (const std::exception& e) {
#pragma omp critical
        if (error.empty()) error = e.what();
        continue;
      }
      size_t points = 0;
      for (const ParticleStore& o : objs) {
        points += o.size();
        mine.bounds.add(framing_bounds(o));
        if (color_by.empty()) continue;
        if (attribute_values(o, color_by, values) == AttribDomain::None) continue;
        mine.found = true;
        for (float v : values)
          if (std::isfinite(v)) {
            mine.vmin = std::min(mine.vmin, v);
            mine.vmax = std::max(mine.vmax, v);
          }
      }
      mine.max_points = std::max(mine.max_points, points);
      if (k == 0 && !objs.empty()) {
        for (const auto& [name, a] : objs[0].attributes()) mine.point_attribs.push_back(name);
        for (const auto& [name, a] : objs[0].prim_attributes()) mine.edge_attribs.push_back(name);
      }
    }
#pragma omp critical
    {
      s.bounds.add(mine.bounds);
      s.vmin = std::min(s.vmin, mine.vmin);
      s.vmax = std::max(s.vmax, mine.vmax);
      s.found = s.found || mine.found;
      s.max_points = std::max(s.max_points, mine.max_points);
      if (!mine.point_attribs.empty() || !mine.edge_attribs.empty()) {
        s.point_attribs = mine.point_attribs;
        s.edge_attribs = mine.edge_attribs;
      }
    }
  }
  if (!error.empty()) throw GeometryError(error);
  return s;
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : " ") + x;
  return s.empty() ? "(none)" : s;
}

// Where the rendered frames go besides PNG: raw RGB frames piped to ffmpeg, which writes the
// video. For a .gif it makes one palette for the whole clip and maps every frame onto it
// (palettegen, paletteuse), at half size above 640 pixels wide, as GIFs are big.
class VideoSink {
 public:
  // Throws BadInput when ffmpeg is not on PATH.
  VideoSink(const std::string& path, int width, int height, double fps) : path_(path) {
    std::string ffmpeg = find_on_path("ffmpeg");
    if (ffmpeg.empty())
      throw BadInput("--video " + path +
                     ": writing a video needs ffmpeg on PATH, and there is none; "
                     "install it (apt-get install ffmpeg)");
    char num[64];
    std::snprintf(num, sizeof num, "%dx%d -framerate %g", width, height, fps);
    std::string output;  // the filter and the output's options
    const std::string ext = lower(fs::path(path).extension().string());
    if (ext == ".gif")
      output = "-vf " + shell_quote(std::string(width > 640 ? "scale=iw/2:ih/2:flags=area," : "") +
                                    "split[a][b];[a]palettegen[p];[b][p]paletteuse");
    else  // yuv420p (what players expect) needs even sizes: pad by a pixel when odd
      output = "-vf " + shell_quote("pad=ceil(iw/2)*2:ceil(ih/2)*2") + " -pix_fmt yuv420p";
    // an MP4 (QuickTime) file with its index first plays in a browser before it has all arrived
    if (ext == ".mp4" || ext == ".m4v" || ext == ".mov") output += " -movflags +faststart";
    const std::string cmd = shell_quote(ffmpeg) +
                            " -y -loglevel error -f rawvideo -pix_fmt rgb24 -s " + num + " -i - " +
                            output + " " + shell_quote(path);
    std::signal(SIGPIPE, SIG_IGN);  // a dying ffmpeg must give a write error, not kill us
    pipe_ = ::popen(cmd.c_str(), "w");
    if (!pipe_) throw std::runtime_error("cannot start " + ffmpeg);
  }
  ~VideoSink() {
    if (pipe_) ::pclose(pipe_);
  }
  void add(const Image& img) {
    if (std::fwrite(img.rgb.data(), 1, img.rgb.size(), pipe_) != img.rgb.size())
      throw std::runtime_error("ffmpeg stopped taking frames for " + path_);
  }
  void finish() {
    int rc = ::pclose(pipe_);
    pipe_ = nullptr;
    if (rc != 0) throw std::runtime_error("ffmpeg failed writing " + path_);
  }

 private:
  std::string path_;
  std::FILE* pipe_ = nullptr;
};

int run(const RenderOptions& opts) {
  using clock = std::chrono::steady_clock;
  auto ms_since = [](clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(clock::now() - t0).count();
  };
  auto t_start = clock::now();
  if (opts.threads > 0) omp_set_num_threads(opts.threads);

  int W = 0, H = 0;
  parse_size(opts.size, W, H);
  std::optional<Camera> given_camera;
  if (!opts.camera.empty()) given_camera = parse_camera(opts.camera, W, H);
  std::vector<std::string> objects;
  std::vector<FrameFiles> frames = scan_frames(opts.dir, objects);

  double fps = 24;
  // the graph is loaded (and checked) for its fps only; its node types are the program's
  // (cli_main registers them)
  if (!opts.graph.empty()) fps = load_graph(opts.graph).fps;
  // --graph asks for the colliders: their poses must be there; without it a folder that has none
  // (written before runs recorded them, or not by a run) is drawn without colliders, with a warning
  RecordedColliders colliders = read_recorded_colliders(opts.dir, objects);
  if (!colliders.missing.empty()) {
    if (!opts.graph.empty())
      throw BadInput("--graph " + opts.graph + ": the colliders are drawn from the poses the run "
                     "recorded, and " + colliders.missing.front() + " does not exist (frames "
                     "written before runs recorded collider poses, or not by `grains run`): run "
                     "the graph again to draw them, or leave out --graph");
    spdlog::warn(
        "grains render: warning: {} does not exist (frames written before runs recorded "
        "collider poses, or not by `grains run`): its colliders are not drawn",
        colliders.missing.front());
  }
  if (opts.fps > 0) fps = opts.fps;

  const std::string out = opts.out.empty() ? (fs::path(opts.dir) / "render").string() : opts.out;
  std::unique_ptr<VideoSink> video;
  // fail before any work when the video cannot be made; its folder must exist (no folders are
  // made outside the ones the user named)
  if (!opts.video.empty()) {
    const fs::path parent = fs::path(opts.video).parent_path();
    if (!parent.empty() && !fs::is_directory(parent))
      throw BadInput("--video " + opts.video + ": the folder " + parent.string() +
                     " does not exist");
  }
  if (!opts.video.empty() && find_on_path("ffmpeg").empty())
    VideoSink(opts.video, W, H, fps);  // throws BadInput with the message

  // ---- pass 1: bounds and colour range over all frames ----
  auto t_survey = clock::now();
  Survey sv = survey(frames, opts.color_by);
  if (!opts.color_by.empty() && !sv.found)
    throw BadInput("--color-by " + opts.color_by +
                   ": no such point or edge attribute in any frame (" + sv.first_file +
                   " has points: " + join(sv.point_attribs) + "; edges: " + join(sv.edge_attribs) +
                   ")");
  double survey_ms = ms_since(t_survey);

  RenderSettings settings;
  settings.supersample = opts.supersample;
  settings.shading = !opts.flat;
  settings.scene = sv.bounds;
  if (!opts.color_by.empty()) {
    settings.color_by.attribute = opts.color_by;
    settings.color_by.min = std::isfinite(sv.vmin) ? sv.vmin : 0.0f;
    settings.color_by.max = std::isfinite(sv.vmax) ? sv.vmax : 1.0f;
  }
  const Camera cam = given_camera ? *given_camera : frame_bounds(sv.bounds, W, H);

  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) throw BadInput(out + ": cannot make the output folder (" + ec.message() + ")");
  if (!opts.video.empty()) {
    video = std::make_unique<VideoSink>(opts.video, W, H, fps);
  }

  // ---- pass 2: render ----
  const std::vector<int> picks =
      contact_sheet_picks(static_cast<int>(frames.size()), opts.sheet_frames);
  const ContactSheetLayout layout = contact_sheet_layout(static_cast<int>(picks.size()), W, H);
  std::vector<Image> thumbs;
  std::vector<int> thumb_numbers;
  double read_ms = 0, render_ms = 0, write_ms = 0;
  size_t next_pick = 0;
  const bool bar =
      isatty(fileno(stderr)) && spdlog::should_log(spdlog::level::info) && !log_verbose();
  for (size_t k = 0; k < frames.size(); ++k) {
    const FrameFiles& f = frames[k];
    const auto t_frame = clock::now();
    auto t0 = t_frame;
    std::vector<ParticleStore> objs = read_objects(f);
    read_ms += ms_since(t0);

    t0 = clock::now();
    std::vector<const ParticleStore*> ptrs;
    size_t points = 0;
    for (const auto& o : objs) {
      ptrs.push_back(&o);
      points += o.size();
    }
    const double st = f.number / fps;
    char caption[96];
    std::snprintf(caption, sizeof caption, "frame %d  t %.3f s  %zu grains", f.number, st, points);
    Image img = render_frame(ptrs, cam, settings, colliders.at(f.number));
    // thumbnails without the caption: the sheet labels them with their frame number
    if (next_pick < picks.size() && picks[next_pick] == static_cast<int>(k)) {
      thumbs.push_back(resize(img, layout.thumb_width, layout.thumb_height));
      thumb_numbers.push_back(f.number);
      ++next_pick;
    }
    draw_caption(img, caption);
    render_ms += ms_since(t0);

    t0 = clock::now();
    char name[64];
    std::snprintf(name, sizeof name, "frame_%04d.png", f.number);
    write_png((fs::path(out) / name).string(), img);
    if (video) video->add(img);
    write_ms += ms_since(t0);
    // the count on a terminal is redrawn in place with '\r', so it is written to stderr directly
    // (spdlog ends every message with a newline); --verbose logs a line a frame instead
    if (bar)
      std::fprintf(stderr, "\rrender: frame %d (%zu/%zu)   ", f.number, k + 1, frames.size());
    spdlog::debug("render: frame {} ({}/{}): {} grains in {:.0f} ms", f.number, k + 1,
                  frames.size(), points, ms_since(t_frame));
  }
  if (bar) std::fputc('\n', stderr);
  if (!colliders.frames_without.empty()) {
    const size_t more = colliders.frames_without.size() - 1;
    spdlog::warn(
        "grains render: warning: {} has no collider poses for frame {}{}: drawn without colliders",
        kColliderPosesFile, colliders.frames_without.front(),
        more ? " and " + std::to_string(more) + " more" : "");
  }
  const std::string sheet_path = (fs::path(out) / "contact_sheet.png").string();
  write_png(sheet_path, contact_sheet(thumbs, thumb_numbers, W, H));
  if (video) video->finish();

  const double n = static_cast<double>(frames.size());
  spdlog::info(
      "render: {} frames of {}x{} (up to {} grains) in {:.2f} s: survey {:.0f} ms, per frame "
      "{:.0f} ms read + {:.0f} ms render + {:.0f} ms write, {} threads",
      frames.size(), W, H, sv.max_points, ms_since(t_start) / 1000.0, survey_ms, read_ms / n,
      render_ms / n, write_ms / n, omp_get_max_threads());
  if (!opts.color_by.empty())
    spdlog::info("render: {} from {} to {} over all frames", opts.color_by,
                 format_value(settings.color_by.min), format_value(settings.color_by.max));
  spdlog::info("render: frames in {}", out);
  spdlog::info("render: contact sheet {}", sheet_path);
  if (video) spdlog::info("render: video {}", opts.video);
  return kOk;
}

}  // namespace

int render_command(const RenderOptions& opts) {
  set_log_level(opts.quiet, opts.verbose);
  try {
    return run(opts);
  } catch (const BadInput& e) {
    spdlog::error("grains render: error: {}", e.what());
    return kBadInput;
  } catch (const LoadError& e) {
    spdlog::error("grains render: error: {}", e.what());
    return kBadInput;
  } catch (const GeometryError& e) {
    spdlog::error("grains render: error: {}", e.what());
    return kBadInput;
  } catch (const std::exception& e) {
    spdlog::error("grains render: failed: {}", e.what());
    return kRunFailure;
  }
}

CLI::App* add_render_subcommand(CLI::App& app, RenderOptions& o) {
  auto* r = app.add_subcommand("render",
                               "render a folder of written frames to PNGs, a contact sheet "
                               "and a video, with no window and no GPU");
  r->add_option("dir", o.dir, "folder of frame_NNNN.ply (or of one sub-folder per object)")
      ->required();
  r->add_option("--out", o.out, "output folder (default DIR/render)");
  r->add_option("--graph", o.graph,
                "graph file: uses its fps, and requires the collider poses its run recorded "
                "(DIR/collider_poses.csv; they are drawn whenever present)");
  r->add_option("--color-by", o.color_by,
                "attribute to colour by: v (speed), id, pscale, strain (edges), any float or int "
                "attribute, a vector (its magnitude) or NAME.x/.y/.z; the range spans all frames");
  r->add_option("--video", o.video,
                "also write a video through ffmpeg: FILE.mp4 (its index first, to play while it "
                "downloads), FILE.gif (one palette for the clip), "
                "or anything ffmpeg writes");
  r->add_option("--camera", o.camera,
                "ex,ey,ez,tx,ty,tz,fov: eye, target, vertical fov in degrees "
                "(default: frames every grain of every frame)");
  r->add_option("--size", o.size, "image size WxH (default 960x540)");
  r->add_option("--fps", o.fps,
                "frames per second for times and the video (default: the graph's, else 24)")
      ->check(positive_number());
  r->add_option("--supersample", o.supersample, "samples per pixel along each axis (default 2)")
      ->check(CLI::Range(1, 4));
  r->add_option("--threads", o.threads, "worker threads (default: all cores)")
      ->check(CLI::Range(1, kMaxThreads));
  r->add_option("--sheet-frames", o.sheet_frames, "frames on the contact sheet (default 12)")
      ->check(CLI::Range(1, 64));
  r->add_flag("--flat", o.flat,
              "flat colours (exactly the colour bar's), no lighting or occlusion");
  add_verbosity_flags(r, o.quiet, o.verbose);
  return r;
}

}  // namespace grains::viewer
