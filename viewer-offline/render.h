// The offline viewer (DESIGN §1, §5): `grains render DIR` turns a folder of written frames
// (DIR/frame_0001.ply …, DESIGN §6) into PNG frames, a contact sheet and a video, without a
// window or a GPU. It reads only what the run wrote: the colliders are drawn where the run posed
// them (DIR/collider_poses.csv, docs/output-format.md), never by evaluating the graph again.
//
// How a frame is drawn (render_frame), at `supersample` times the camera's resolution:
//   1. grains: each sphere is splatted over its exact screen-space bounding box; every pixel of
//      the box casts its ray against the sphere and keeps the nearest true hit depth in a
//      per-pixel z-buffer (no painter's sort). Spheres are binned into 32x32 tiles and the tiles
//      run in parallel (OpenMP); within a tile spheres go in index order and a depth tie keeps
//      the lower index, so the image is the same for any thread count;
//   2. planes: ray-plane hits on a finite, gridded ground patch, depth-tested the same way;
//   3. shading, per pixel: Lambert key + fill light, ambient, a rim darkening and a screen-space
//      ambient occlusion read from the z-buffer; the other colliders (box, sphere, torus,
//      capsule) are sphere-traced with their exact signed distances up to the z-buffer depth and
//      laid over translucently;
//   4. box-filtered down to the camera's size; edges (constraints) are then drawn as anti-aliased
//      lines, depth-tested against the grains; captions and the colour bar go on top.
#pragma once
#include <string>
#include <vector>

#include "engine/collider.h"
#include "engine/particles.h"
#include "engine/vec3.h"
#include "viewer-offline/image.h"

namespace CLI {
class App;
}

namespace grains::viewer {

// Axis-aligned box; empty until something is added.
struct Bounds {
  Vec3 lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
  bool valid() const { return lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z; }
  void add(const Vec3& p, float r = 0);  // a point, or a sphere of radius r; ignores non-finite
  void add(const Bounds& b);
  Vec3 center() const { return (lo + hi) * 0.5f; }
  Vec3 size() const { return hi - lo; }
};

// A pinhole camera looking from `eye` at `target`, world +y up (+z when looking straight down
// or up), with a vertical field of view. Pixel (i, j) covers [i, i+1) x [j, j+1) with j = 0 at
// the top, so its centre projects from (i + 0.5, j + 0.5).
struct Camera {
  Vec3 eye{3, 2, 3}, target{0, 0, 0};
  float fov_deg = 35;  // vertical field of view (degrees)
  int width = 960, height = 540;
  // derived (look_at): orthonormal basis and the focal length in pixels
  Vec3 right{1, 0, 0}, up{0, 1, 0}, forward{0, 0, -1};
  float focal = 1;  // (height / 2) / tan(fov / 2)

  static Camera look_at(const Vec3& eye, const Vec3& target, float fov_deg, int width, int height);
  // world → camera space (x right, y up, z forward = depth in m)
  Vec3 to_camera(const Vec3& p) const {
    Vec3 d = p - eye;
    return {dot(d, right), dot(d, up), dot(d, forward)};
  }
  Vec3 to_world(const Vec3& c) const { return eye + right * c.x + up * c.y + forward * c.z; }
  // World point → continuous pixel coordinates and depth; false when not in front of the camera.
  bool project(const Vec3& p, float* px, float* py, float* depth) const;
  // Camera-space direction through pixel coordinates (px, py), with z = 1 (so a ray parameter
  // equals depth).
  Vec3 ray(float px, float py) const {
    return {(px - 0.5f * width) / focal, -(py - 0.5f * height) / focal, 1.0f};
  }
  // The same view at `factor` times the resolution.
  Camera scaled(int factor) const;
};

// A camera that frames `box` from a pleasant three-quarter view: azimuth measured from +z
// towards +x, elevation above the horizon, the box's corners filling about 90% of the frame.
Camera frame_bounds(const Bounds& box, int width, int height, float fov_deg = 35,
                    float azimuth_deg = 35, float elevation_deg = 25);

// ---- colour ----------------------------------------------------------------------------------

// What an attribute colours: nothing (absent), the points or the edges (primitives).
enum class AttribDomain { None, Point, Edge };

// Per-point (or per-edge) values of `attr`: Float and Int as they are, vectors as their magnitude
// (so `v` is the speed |v|), `NAME.x` / `.y` / `.z` one component; a point attribute wins over a
// primitive attribute of the same name (`strain` is an edge attribute). Returns None, leaving
// `out` empty, when the store has no such attribute.
AttribDomain attribute_values(const ParticleStore& pts, const std::string& attr,
                              std::vector<float>& out);

// The colour ramp (viridis-like, dark blue → green → yellow); t is clamped to [0, 1].
Rgb colormap(float t);

struct ColorBy {
  std::string attribute;       // empty: every grain in the sand colour
  float min = 0, max = 1;      // mapped onto the colour bar, bottom (min) to top (max)
  float t(float value) const;  // value → [0, 1]
};

// Pixel rectangle [x0, x1) x [y0, y1) of the colour bar in a width x height frame: row y1 - 1
// shows colormap(0) (the minimum), row y0 colormap(1) (the maximum).
struct Rect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};
Rect color_bar_rect(int width, int height);
// Draws the bar with the attribute's name and its min / max labels.
void draw_color_bar(Image& img, const ColorBy& c);
// "%.3g"-style label for a bar end (digits, '.', '-', 'e').
std::string format_value(double v);

// ---- frames ----------------------------------------------------------------------------------

struct RenderSettings {
  ColorBy color_by;
  Rgb sand{0.80f, 0.66f, 0.45f};        // grain colour when not coloured by an attribute
  Rgb edge_color{0.16f, 0.13f, 0.11f};  // edge colour when edges are not coloured
  bool shading = true;          // false: flat albedo, no lighting or occlusion (exact colours)
  bool grain_variation = true;  // +-6% brightness per grain id, for a natural sand look
  int supersample = 2;          // rendered at this multiple of the camera's size, box-filtered down
  bool draw_edges = true;
  float edge_width = 1.5f;  // pixels
  bool color_bar = true;    // when colouring by an attribute
  std::string caption;      // top-left text, e.g. "frame 12  t 0.500 s"
  // Scene extent (e.g. the grains over all frames) that sizes the ground patch of each plane
  // collider; when invalid, the patch is 4 m wide around the plane's origin.
  Bounds scene;
};

// Renders one or several particle objects together, with optional colliders (their end-of-frame
// pose). The image has the camera's size and a depth channel (camera z, +inf for background).
Image render_frame(const std::vector<const ParticleStore*>& objects, const Camera& cam,
                   const RenderSettings& settings,
                   const std::vector<ColliderState>& colliders = {});
Image render_frame(const ParticleStore& pts, const Camera& cam, const RenderSettings& settings,
                   const std::vector<ColliderState>& colliders = {});

// Draws a one-line caption on a light panel in the top-left corner.
void draw_caption(Image& img, const std::string& text);

// ---- contact sheet ---------------------------------------------------------------------------

// Thumbnails are frames shrunk 4x, `columns` per row (at most 4), `gap` pixels apart and around.
struct ContactSheetLayout {
  int columns = 0, rows = 0, thumb_width = 0, thumb_height = 0, gap = 4, width = 0, height = 0;
};
ContactSheetLayout contact_sheet_layout(int count, int frame_width, int frame_height);
// Which of `count` frames the sheet shows: all when count <= max_thumbs, else max_thumbs evenly
// spaced ones, first and last included (indices into the frame list).
std::vector<int> contact_sheet_picks(int count, int max_thumbs = 12);
// Builds the sheet for frames of frame_width x frame_height, labelled with their numbers; each
// image is either already thumbnail-sized (pasted as is) or shrunk to fit.
Image contact_sheet(const std::vector<Image>& frames, const std::vector<int>& frame_numbers,
                    int frame_width, int frame_height);

// ---- the command -----------------------------------------------------------------------------

struct RenderOptions {
  std::string dir;       // folder of frame_NNNN.ply (or of one sub-folder per object)
  std::string out;       // output folder; default DIR/render
  std::string graph;     // graph file: its fps; asks for the colliders the run recorded
  std::string color_by;  // attribute to colour by
  std::string video;     // .mp4 (or anything ffmpeg writes) via ffmpeg; .gif written here
  std::string camera;    // "ex,ey,ez,tx,ty,tz,fov"; empty = frame everything
  std::string size = "960x540";
  double fps = 0;  // 0: the graph's fps, else 24
  int supersample = 2;
  int threads = 0;        // 0: OpenMP's default
  int sheet_frames = 12;  // thumbnails on the contact sheet
  bool flat = false;      // flat colours: no lighting or occlusion
  bool quiet = false;    // errors and warnings only
  bool verbose = false;  // also a line a frame
};

// Renders the folder; returns the exit code (0 ok, 2 bad input, 1 failure while rendering).
// Sets the log level (cli/log.h) from quiet and verbose; messages go to stderr.
int render_command(const RenderOptions& opts);

// Adds the `render` subcommand's arguments to a CLI11 app, bound to `opts`.
CLI::App* add_render_subcommand(CLI::App& app, RenderOptions& opts);

}  // namespace grains::viewer
