// The offline viewer: projection, z-buffered spheres, colour-by and its bar, edges, colliders,
// the contact sheet, the render command's files, videos through ffmpeg and exit codes.
#include <omp.h>
#include <sys/wait.h>

#include <catch2/catch.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "engine/collider_poses.h"
#include "engine/geometry_io.h"
#include "tests/support/png.h"
#include "tests/support/support.h"
#include "viewer-offline/render.h"

using namespace grains;
using namespace grains::viewer;

namespace {

// A store of spheres at `centres` with radius `r` and a float attribute `tag`.
ParticleStore spheres(const std::vector<Vec3>& centres, const std::vector<float>& radii,
                      const std::vector<float>& tags = {}) {
  ParticleStore pts;
  pts.add_points(centres.size());
  float* P = pts.v3("P");
  float* ps = pts.f("pscale");
  float* tag = pts.f("tag");
  for (size_t i = 0; i < centres.size(); ++i) {
    store3(P, i, centres[i]);
    ps[i] = radii[i];
    tag[i] = i < tags.size() ? tags[i] : 0.0f;
  }
  return pts;
}

// Flat colours at one sample per pixel: a pixel shows exactly its surface's albedo.
RenderSettings flat(const std::string& color_by = "", float lo = 0, float hi = 1) {
  RenderSettings s;
  s.shading = false;
  s.supersample = 1;
  s.grain_variation = false;
  s.color_bar = false;
  s.color_by.attribute = color_by;
  s.color_by.min = lo;
  s.color_by.max = hi;
  return s;
}

struct Px {
  int r, g, b;
  bool operator==(const Px& o) const { return r == o.r && g == o.g && b == o.b; }
};
Px pixel(const Image& img, int x, int y) {
  const uint8_t* p = img.px(x, y);
  return {p[0], p[1], p[2]};
}
Px bytes(const Rgb& c) {
  return {to_byte(c.r), to_byte(c.g), to_byte(c.b)};
}
std::ostream& operator<<(std::ostream& os, const Px& p) {
  return os << "(" << p.r << "," << p.g << "," << p.b << ")";
}

// The pinhole projection worked out here, independently of Camera: returns pixel coordinates
// (pixel (i, j)'s centre at (i + 0.5, j + 0.5), j down) and the focal length in pixels.
void pinhole(Vec3 eye, Vec3 target, float fov_deg, int w, int h, Vec3 p, float* px, float* py,
             float* focal) {
  Vec3 f = normalized(target - eye);
  Vec3 r = normalized(cross(f, Vec3{0, 1, 0}));
  Vec3 u = cross(r, f);
  *focal = 0.5f * h / std::tan(0.5f * fov_deg * static_cast<float>(M_PI) / 180.0f);
  Vec3 d = p - eye;
  float z = dot(d, f);
  *px = 0.5f * w + *focal * dot(d, r) / z;
  *py = 0.5f * h - *focal * dot(d, u) / z;
}

}  // namespace

TEST_CASE("a single sphere lands at its pinhole projection with its projected radius", "[viewer]") {
  const Vec3 eye{0.4f, 0.6f, 3.0f}, target{0, 0, 0};
  const int W = 200, H = 150;
  const float fov = 40;
  const Vec3 c{0.25f, 0.1f, -0.1f};
  const float r = 0.15f;
  Camera cam = Camera::look_at(eye, target, fov, W, H);
  Image img = render_frame(spheres({c}, {r}), cam, flat());

  float ex, ey, f;
  pinhole(eye, target, fov, W, H, c, &ex, &ey, &f);
  // the disc is the set of pixels with a finite depth; its centroid and equivalent radius
  double sx = 0, sy = 0, n = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      if (std::isfinite(img.depth[static_cast<size_t>(y) * W + x])) {
        sx += x + 0.5;
        sy += y + 0.5;
        n += 1;
      }
  REQUIRE(n > 0);
  CHECK(std::fabs(sx / n - ex) < 1.0);
  CHECK(std::fabs(sy / n - ey) < 1.0);
  // a sphere at distance d subtends a cone of half-angle asin(r / d): its image is a disc (to
  // first order off the axis) of radius f * tan(asin(r / d)) = f r / sqrt(d^2 - r^2)
  float d = length(c - eye);
  double expected_radius = f * r / std::sqrt(d * d - r * r);
  double measured_radius = std::sqrt(n / M_PI);
  CHECK(std::fabs(measured_radius - expected_radius) < 1.0);
  // and the row through the centre is as wide as the disc
  int row = static_cast<int>(ey), left = W, right = -1;
  for (int x = 0; x < W; ++x)
    if (std::isfinite(img.depth[static_cast<size_t>(row) * W + x])) {
      left = std::min(left, x);
      right = std::max(right, x);
    }
  CHECK(std::fabs((right - left + 1) / 2.0 - expected_radius) < 1.0);
  // Camera::project agrees with the independent projection
  float px, py, depth;
  REQUIRE(cam.project(c, &px, &py, &depth));
  CHECK(px == Approx(ex).margin(1e-3));
  CHECK(py == Approx(ey).margin(1e-3));
  // the depth at the disc's centre is the sphere's front surface, about d - r
  CHECK(img.depth[static_cast<size_t>(ey) * W + static_cast<size_t>(ex)] ==
        Approx(dot(c - eye, cam.forward) - r).margin(0.01));
}

TEST_CASE("nearer spheres hide farther ones, per pixel", "[viewer]") {
  const Vec3 eye{0, 0, 5}, target{0, 0, 0};
  const int W = 160, H = 120;
  Camera cam = Camera::look_at(eye, target, 30, W, H);
  const Px near_colour = bytes(colormap(0)), far_colour = bytes(colormap(1));

  SECTION("separate spheres: the nearer one covers the overlap, whatever the order") {
    for (bool near_first : {true, false}) {
      std::vector<Vec3> c = {{0, 0, 1}, {0.15f, 0, -1}};
      std::vector<float> tag = {0, 1};
      if (!near_first) {
        std::swap(c[0], c[1]);
        std::swap(tag[0], tag[1]);
      }
      Image img = render_frame(spheres(c, {0.3f, 0.3f}, tag), cam, flat("tag"));
      float px, py;
      cam.project({0.05f, 0, 1.3f}, &px, &py, nullptr);  // inside both discs
      CHECK(pixel(img, static_cast<int>(px), static_cast<int>(py)) == near_colour);
    }
  }
  SECTION("intersecting spheres: each pixel shows the surface nearest the eye") {
    // big (tag 1) at the origin, small (tag 0) at (0.4, 0, 0.15): the small centre is nearer, so
    // a painter's sort would draw the small one over the big one everywhere; but at x = 0.25 the
    // big surface (z = sqrt(0.5^2 - 0.25^2) = 0.433) is nearer than the small one (z = 0.15 +
    // sqrt(0.2^2 - 0.15^2) = 0.282), and at x = 0.45 the small one (z = 0.344) beats the big
    // (0.218)
    Image img = render_frame(spheres({{0, 0, 0}, {0.4f, 0, 0.15f}}, {0.5f, 0.2f}, {1, 0}), cam,
                             flat("tag"));
    float px, py;
    cam.project({0.25f, 0, 0.433f}, &px, &py, nullptr);
    CHECK(pixel(img, static_cast<int>(px), static_cast<int>(py)) == far_colour);
    cam.project({0.45f, 0, 0.344f}, &px, &py, nullptr);
    CHECK(pixel(img, static_cast<int>(px), static_cast<int>(py)) == near_colour);
  }
}

TEST_CASE("colour-by maps the minimum and maximum onto the colour bar's ends", "[viewer]") {
  const int W = 240, H = 160;
  Camera cam = Camera::look_at({0, 0, 5}, {0, 0, 0}, 30, W, H);
  std::vector<Vec3> c = {{-0.8f, 0, 0}, {0, 0, 0}, {0.6f, 0, 0}};
  RenderSettings s = flat("tag", -2, 5);
  s.color_bar = true;
  Image img = render_frame(spheres(c, {0.15f, 0.15f, 0.15f}, {-2, 1, 5}), cam, s);
  Rect bar = color_bar_rect(W, H);
  REQUIRE(bar.x1 <= W);
  REQUIRE(bar.y1 <= H);
  int bx = (bar.x0 + bar.x1) / 2;
  Px bottom = pixel(img, bx, bar.y1 - 1), top = pixel(img, bx, bar.y0);
  CHECK(bottom == bytes(colormap(0)));
  CHECK(top == bytes(colormap(1)));
  float px, py;
  cam.project(c[0], &px, &py, nullptr);
  CHECK(pixel(img, static_cast<int>(px), static_cast<int>(py)) == bottom);
  cam.project(c[2], &px, &py, nullptr);
  CHECK(pixel(img, static_cast<int>(px), static_cast<int>(py)) == top);
  cam.project(c[1], &px, &py, nullptr);  // 1 is 3/7 of the way up
  CHECK(pixel(img, static_cast<int>(px), static_cast<int>(py)) == bytes(colormap(3.0f / 7.0f)));

  SECTION("vectors colour by magnitude, components by NAME.x, edges by their attributes") {
    ParticleStore p = spheres(c, {0.1f, 0.1f, 0.1f});
    store3(p.v3("v"), 0, {3, 4, 0});
    std::vector<float> vals;
    REQUIRE(attribute_values(p, "v", vals) == AttribDomain::Point);
    CHECK(vals[0] == Approx(5));
    REQUIRE(attribute_values(p, "v.y", vals) == AttribDomain::Point);
    CHECK(vals[0] == Approx(4));
    REQUIRE(attribute_values(p, "id", vals) == AttribDomain::Point);
    CHECK(vals[2] == Approx(2));
    p.add_prim(0, 1);
    p.prim_f("strain")[0] = 0.25f;
    REQUIRE(attribute_values(p, "strain", vals) == AttribDomain::Edge);
    CHECK(vals[0] == Approx(0.25));
    CHECK(attribute_values(p, "nothing", vals) == AttribDomain::None);
    CHECK(format_value(-0.000123) == "-0.000123");
    CHECK(format_value(1.5e7) == "1.5e+07");
  }
}

TEST_CASE("edges are drawn as depth-tested lines", "[viewer]") {
  const int W = 160, H = 121;  // odd: the line y = 0 runs through the centres of row 60
  Camera cam = Camera::look_at({0, 0, 5}, {0, 0, 0}, 30, W, H);
  RenderSettings s = flat();
  s.edge_color = {1, 0, 0};
  // two small grains 1 m apart joined by an edge, and a big grain in front of part of it
  ParticleStore p = spheres({{-0.5f, 0, 0}, {0.5f, 0, 0}, {0.35f, 0, 1.5f}}, {0.05f, 0.05f, 0.12f});
  p.add_prim(0, 1);
  Image img = render_frame(p, cam, s);
  Image bare = render_frame(
      spheres({{-0.5f, 0, 0}, {0.5f, 0, 0}, {0.35f, 0, 1.5f}}, {0.05f, 0.05f, 0.12f}), cam, s);
  float px, py;
  cam.project({-0.1f, 0, 0}, &px, &py, nullptr);  // on the line, in the open
  Px on_line = pixel(img, static_cast<int>(px), static_cast<int>(py));
  CHECK(on_line.r > 200);
  CHECK(on_line.g < 60);
  CHECK_FALSE(on_line == pixel(bare, static_cast<int>(px), static_cast<int>(py)));
  // behind the big grain the line is hidden
  cam.project({0.35f, 0, 1.5f}, &px, &py, nullptr);
  CHECK(pixel(img, static_cast<int>(px), static_cast<int>(py)) ==
        pixel(bare, static_cast<int>(px), static_cast<int>(py)));
}

TEST_CASE("colliders are drawn and depth-tested against grains", "[viewer]") {
  const int W = 160, H = 120;
  Camera cam = Camera::look_at({0, 1, 5}, {0, 0, 0}, 35, W, H);
  ColliderState ground;  // plane y = 0
  ColliderState ball;
  ball.shape.kind = ShapeKind::Sphere;
  ball.shape.radius = 0.4f;
  ball.pose.t = {-0.6f, 0.4f, 0};
  ColliderState torus;
  torus.shape.kind = ShapeKind::Torus;
  torus.shape.radius = 0.3f;
  torus.shape.tube = 0.08f;
  torus.pose = Pose::from_trs({0.6f, 0.3f, 0}, {90, 0, 0}, 1);
  RenderSettings s = flat();
  s.sand = {1, 0, 1};
  // a grain in front of the ball
  ParticleStore p = spheres({{-0.6f, 0.4f, 1.0f}}, {0.1f});
  Image none = render_frame(p, cam, s);
  Image img = render_frame(p, cam, s, {ground, ball, torus});
  float px, py;
  // the ball's centre direction, beside the grain: the ball's colour, not background
  cam.project({-0.6f, 0.6f, 0.39f}, &px, &py, nullptr);
  CHECK_FALSE(pixel(img, static_cast<int>(px), static_cast<int>(py)) ==
              pixel(none, static_cast<int>(px), static_cast<int>(py)));
  // the grain in front of the ball keeps its own colour
  cam.project({-0.6f, 0.4f, 1.0f}, &px, &py, nullptr);
  CHECK(pixel(img, static_cast<int>(px), static_cast<int>(py)) == bytes(s.sand));
  // the torus's tube (ring in the xy plane after the 90 degree turn), and its empty middle
  cam.project({0.6f + 0.3f, 0.3f, 0.08f}, &px, &py, nullptr);
  CHECK_FALSE(pixel(img, static_cast<int>(px), static_cast<int>(py)) ==
              pixel(none, static_cast<int>(px), static_cast<int>(py)));
  // the ground in front of everything, below the objects
  cam.project({0, 0, 1.5f}, &px, &py, nullptr);
  CHECK_FALSE(pixel(img, static_cast<int>(px), static_cast<int>(py)) ==
              pixel(none, static_cast<int>(px), static_cast<int>(py)));
  CHECK(std::isfinite(img.depth[static_cast<size_t>(py) * W + static_cast<size_t>(px)]));
}

TEST_CASE("the image does not depend on the thread count", "[viewer]") {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-0.5f, 0.5f);
  std::vector<Vec3> c;
  std::vector<float> r;
  for (int i = 0; i < 3000; ++i) {
    c.push_back({u(rng), u(rng), u(rng)});
    r.push_back(0.02f + 0.02f * (u(rng) + 0.5f));
  }
  ParticleStore p = spheres(c, r);
  Camera cam = frame_bounds(Bounds{{-0.5f, -0.5f, -0.5f}, {0.5f, 0.5f, 0.5f}}, 160, 90);
  RenderSettings s;
  ColliderState ground;
  ground.pose.t = {0, -0.5f, 0};
  int before = omp_get_max_threads();
  omp_set_num_threads(1);
  Image one = render_frame(p, cam, s, {ground});
  omp_set_num_threads(3);
  Image three = render_frame(p, cam, s, {ground});
  omp_set_num_threads(before);
  CHECK(one.rgb == three.rgb);
}

TEST_CASE("the default camera frames the bounds", "[viewer]") {
  Bounds b;
  b.add({-1, 0, -0.5f});
  b.add({2, 0.5f, 0.5f});
  const int W = 320, H = 180;
  Camera cam = frame_bounds(b, W, H);
  for (int k = 0; k < 8; ++k) {
    Vec3 p{(k & 1) ? b.hi.x : b.lo.x, (k & 2) ? b.hi.y : b.lo.y, (k & 4) ? b.hi.z : b.lo.z};
    float px, py;
    REQUIRE(cam.project(p, &px, &py, nullptr));
    CHECK(px >= 0);
    CHECK(px <= W);
    CHECK(py >= 0);
    CHECK(py <= H);
  }
  // looking down on it from a three-quarter view
  CHECK(cam.eye.y > b.hi.y);
  CHECK(cam.eye.x > b.center().x);
  CHECK(cam.eye.z > b.center().z);
}

TEST_CASE("contact sheet layout and picks", "[viewer]") {
  ContactSheetLayout l = contact_sheet_layout(12, 960, 540);
  CHECK(l.columns == 4);
  CHECK(l.rows == 3);
  CHECK(l.width == 4 * 240 + 5 * 4);
  CHECK(l.height == 3 * 135 + 4 * 4);
  CHECK(contact_sheet_picks(5) == std::vector<int>{0, 1, 2, 3, 4});
  std::vector<int> picks = contact_sheet_picks(96);
  REQUIRE(picks.size() == 12);
  CHECK(picks.front() == 0);
  CHECK(picks.back() == 95);
  for (size_t k = 1; k < picks.size(); ++k) CHECK(picks[k] > picks[k - 1]);
}

namespace {
// Writes frames 1 and 2 of a small scene: a sphere whose `heat` is 0 then 10, with an edge.
std::string two_frames() {
  std::string dir = test::temp_dir("render");
  for (int f = 1; f <= 2; ++f) {
    ParticleStore p = spheres({{0, 0.3f, 0}, {0.4f, 0.3f, 0}}, {0.1f, 0.1f});
    p.f("heat")[0] = f == 1 ? 0.0f : 10.0f;
    p.f("heat")[1] = 5;
    p.add_prim(0, 1);
    char name[32];
    std::snprintf(name, sizeof name, "/frame_%04d.ply", f);
    write_ply(dir + name, p, {"heat"});
  }
  return dir;
}
}  // namespace

TEST_CASE("render command: a folder of 2 frames gives 2 PNGs and a contact sheet", "[viewer]") {
  std::string dir = two_frames();
  RenderOptions o;
  o.dir = dir;
  o.size = "96x64";
  o.quiet = true;
  o.color_by = "heat";
  o.flat = true;
  o.supersample = 1;
  o.camera = "0.2,0.3,3,0.2,0.3,0,30";  // the hot grain sits left of the colour bar's panel
  REQUIRE(render_command(o) == 0);
  int w = 0, h = 0;
  REQUIRE(test::png_size(dir + "/render/frame_0001.png", &w, &h));
  CHECK(w == 96);
  CHECK(h == 64);
  REQUIRE(test::png_size(dir + "/render/frame_0002.png", &w, &h));
  CHECK_FALSE(std::filesystem::exists(dir + "/render/frame_0003.png"));
  ContactSheetLayout l = contact_sheet_layout(2, 96, 64);
  REQUIRE(test::png_size(dir + "/render/contact_sheet.png", &w, &h));
  CHECK(w == l.width);
  CHECK(h == l.height);
  CHECK(w == 2 * 24 + 3 * 4);  // two thumbnails of 96/4 x 64/4 with 4-pixel gaps
  CHECK(h == 16 + 2 * 4);

  SECTION("the colour range spans all frames: frame 1 shows the minimum, frame 2 the maximum") {
    Camera cam = Camera::look_at({0.2f, 0.3f, 3}, {0.2f, 0.3f, 0}, 30, 96, 64);
    float px, py;
    cam.project({0, 0.3f, 0.1f}, &px, &py, nullptr);
    Rect bar = color_bar_rect(96, 64);
    for (int f = 1; f <= 2; ++f) {
      const std::optional<test::Png> png =
          test::read_png(dir + "/render/frame_000" + std::to_string(f) + ".png");
      REQUIRE(png);
      auto at = [&](int x, int y) {
        const unsigned char* q = png->at(x, y);
        return Px{q[0], q[1], q[2]};
      };
      Px grain = at(static_cast<int>(px), static_cast<int>(py));
      Px end = at((bar.x0 + bar.x1) / 2, f == 1 ? bar.y1 - 1 : bar.y0);
      CHECK(grain == end);
    }
  }
}

TEST_CASE("render command: colliders from the run, the grains binary, exit codes", "[viewer]") {
  std::string dir = two_frames();
  std::string graph = test::write_file(dir, "g.json", R"({
    "grains_graph": 1, "name": "r", "fps": 24, "frames": 2,
    "nodes": [
      {"name": "src", "type": "source", "params": {"shape": "box", "size": [0.1, 0.1, 0.1]}},
      {"name": "ground", "type": "collider", "params": {"shape": "plane"}},
      {"name": "ball", "type": "collider", "params": {"shape": "sphere", "radius": 0.2, "translate": [0, "0.2 + $ST", 0]}},
      {"name": "box", "type": "collider", "params": {"shape": "box", "size": [0.2, 0.1, 0.3], "translate": [0.5, 0, 0]}},
      {"name": "ring", "type": "collider", "params": {"shape": "torus", "radius": 0.3, "tube": 0.05}},
      {"name": "pill", "type": "collider", "params": {"shape": "capsule", "radius": 0.05, "height": 0.3, "translate": [-0.4, 0.2, 0]}},
      {"name": "solver", "type": "solver", "inputs": ["src"], "params": {"colliders": ["ground", "ball", "box", "ring", "pill"]}}
    ]})");
  std::string log = dir + "/log.txt";
  std::string sim = dir + "/sim";
  std::string out = dir + "/pictures";
  REQUIRE(test::run_grains("run " + graph + " --out " + sim + " --quiet", log) == 0);
  CHECK(test::run_grains("render " + sim + " --graph " + graph + " --out " + out +
                             " --size 96x64 --color-by v",
                         log) == 0);
  INFO(test::read_text(log));
  CHECK(test::read_text(log).find("warning") == std::string::npos);
  CHECK(std::filesystem::exists(out + "/frame_0001.png"));
  CHECK(std::filesystem::exists(out + "/frame_0002.png"));
  CHECK(std::filesystem::exists(out + "/contact_sheet.png"));

  SECTION("bad input exits 2 with a message") {
    CHECK(test::run_grains("render " + dir + "/missing", log) == 2);
    CHECK(test::read_text(log).find("not a folder") != std::string::npos);
    CHECK(test::run_grains("render " + dir + " --size 64by48", log) == 2);
    CHECK(test::run_grains("render " + dir + " --camera 1,2,3", log) == 2);
    CHECK(test::run_grains("render " + dir + " --color-by nothing", log) == 2);
    CHECK(test::read_text(log).find("heat") != std::string::npos);  // lists what there is
    CHECK(test::run_grains("render " + dir + " --graph " + dir + "/none.json", log) == 2);
  }
  SECTION("an mp4 without ffmpeg on PATH exits 2 and says so") {
    std::string empty = test::temp_dir("nopath");
    // run the binary itself with a PATH that has no ffmpeg
    std::string cmd = "PATH=" + empty + " " + std::string(GRAINS_BINARY) + " render " + dir +
                      " --size 32x24 --video " + dir + "/a.mp4 > " + log + " 2>&1";
    int rc = std::system(cmd.c_str());
    CHECK(WEXITSTATUS(rc) == 2);
    CHECK(test::read_text(log).find("ffmpeg") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir + "/a.mp4"));
    // a GIF too: ffmpeg makes it
    cmd = "PATH=" + empty + " " + std::string(GRAINS_BINARY) + " render " + dir +
          " --size 32x24 --video " + dir + "/a.gif > " + log + " 2>&1";
    rc = std::system(cmd.c_str());
    CHECK(WEXITSTATUS(rc) == 2);
    CHECK(test::read_text(log).find("needs ffmpeg on PATH") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir + "/a.gif"));
  }
  SECTION("with ffmpeg on PATH, raw RGB frames are piped to it") {
    // a stand-in ffmpeg that records its arguments and copies stdin into the output file
    std::string bin = test::temp_dir("fakeffmpeg");
    std::string script = test::write_file(
        bin, "ffmpeg",
        "#!/bin/sh\necho \"$@\" > " + bin + "/args\nfor last; do :; done\ncat > \"$last\"\n");
    std::filesystem::permissions(script, std::filesystem::perms::owner_all);
    std::string cmd = "PATH=" + bin + ":$PATH " + std::string(GRAINS_BINARY) + " render " + dir +
                      " --size 32x24 --fps 12 --video " + dir + "/a.mp4 > " + log + " 2>&1";
    int rc = std::system(cmd.c_str());
    INFO(test::read_text(log));
    CHECK(WEXITSTATUS(rc) == 0);
    CHECK(std::filesystem::file_size(dir + "/a.mp4") == 2u * 32 * 24 * 3);
    std::string args = test::read_text(bin + "/args");
    CHECK(args.find("-pix_fmt rgb24 -s 32x24 -framerate 12") != std::string::npos);
    CHECK(args.find("-pix_fmt yuv420p") != std::string::npos);
    CHECK(args.find("-movflags +faststart") != std::string::npos);  // the index first
    // a GIF: one palette for the clip (palettegen, paletteuse), half size above 640 pixels
    for (const std::string size : {"32x24", "642x24"}) {
      const bool wide = size == "642x24";
      cmd = "PATH=" + bin + ":$PATH " + std::string(GRAINS_BINARY) + " render " + dir +
            " --size " + size + " --supersample 1 --video " + dir + "/a.gif > " + log + " 2>&1";
      rc = std::system(cmd.c_str());
      INFO(test::read_text(log));
      CHECK(WEXITSTATUS(rc) == 0);
      args = test::read_text(bin + "/args");
      CHECK(args.find("-pix_fmt rgb24 -s " + size) != std::string::npos);
      CHECK(args.find("split[a][b];[a]palettegen[p];[b][p]paletteuse") != std::string::npos);
      CHECK((args.find("scale=iw/2:ih/2") != std::string::npos) == wide);
      CHECK(args.find("faststart") == std::string::npos);  // an MP4 muxer's flag
      // the stand-in copies the raw frames: two at full size, ffmpeg scales
      CHECK(std::filesystem::file_size(dir + "/a.gif") == 2u * 3 * 24 * (wide ? 642 : 32));
    }
  }
  SECTION("the real ffmpeg writes an MP4 that streams: its index (moov) before its frames") {
    // ffmpeg is one of the packages scripts/install-deps.sh installs (make test runs it)
    REQUIRE(std::system("command -v ffmpeg > /dev/null") == 0);
    REQUIRE(test::run_grains("render " + sim + " --out " + out + " --size 64x48 --video " + dir +
                                 "/real.mp4 --quiet",
                             log) == 0);
    // the top-level boxes in order: (size, type) each, a size of 1 giving a 64-bit size after
    const std::string mp4 = test::read_text(dir + "/real.mp4");
    std::vector<std::string> boxes;
    for (size_t at = 0; at + 8 <= mp4.size();) {
      auto byte = [&](size_t k) { return uint64_t(static_cast<unsigned char>(mp4[at + k])); };
      uint64_t size = byte(0) << 24 | byte(1) << 16 | byte(2) << 8 | byte(3);
      boxes.push_back(mp4.substr(at + 4, 4));
      if (size == 1 && at + 16 <= mp4.size()) {
        size = 0;
        for (size_t k = 8; k < 16; ++k) size = size << 8 | byte(k);
      }
      if (size < 8) break;
      at += size;
    }
    INFO(boxes.size() << " boxes");
    const auto moov = std::find(boxes.begin(), boxes.end(), "moov");
    const auto mdat = std::find(boxes.begin(), boxes.end(), "mdat");
    REQUIRE(moov != boxes.end());
    REQUIRE(mdat != boxes.end());
    CHECK(moov < mdat);
  }
}

namespace {
// Two solvers share a ball placed by the object's own variables: at x = 0.5 $OBJID - 0.25 and
// y = 0.3 + 0.1 $NOBJ + $ST, so each solver meets it somewhere else (OBJID 0 and 1, NOBJ 2);
// solver a also has a box. No plane: a plane's ground patch is sized by the grains' bounds.
const char* kPerObjectGraph = R"({
  "grains_graph": 1, "name": "objects", "fps": 24, "frames": 2,
  "nodes": [
    {"name": "sa", "type": "source", "params": {"shape": "box", "center": [-0.25, 0.1, 0], "size": [0.1, 0.1, 0.1], "separation": 0.05}},
    {"name": "sb", "type": "source", "params": {"shape": "box", "center": [0.25, 0.1, 0], "size": [0.1, 0.1, 0.1], "separation": 0.05}},
    {"name": "ball", "type": "collider", "params": {"shape": "sphere", "radius": 0.12,
      "translate": ["0.5 * $OBJID - 0.25", "0.3 + 0.1 * $NOBJ + $ST", 0]}},
    {"name": "box", "type": "collider", "params": {"shape": "box", "size": [0.2, 0.05, 0.2], "translate": [0, -0.1, 0], "rotate": [0, 30, 0]}},
    {"name": "a", "type": "solver", "inputs": ["sa"], "params": {"colliders": ["box", "ball"]}},
    {"name": "b", "type": "solver", "inputs": ["sb"], "params": {"colliders": ["ball"]}}
  ]})";

bool same_pose(const ColliderState& a, const ColliderState& b) {
  bool same = a.name == b.name && a.shape.kind == b.shape.kind && a.shape.radius == b.shape.radius &&
              a.pose.t.x == b.pose.t.x && a.pose.t.y == b.pose.t.y && a.pose.t.z == b.pose.t.z &&
              a.pose.s == b.pose.s;
  for (int k = 0; k < 9; ++k) same = same && a.pose.R[k] == b.pose.R[k];
  return same;
}
}  // namespace

TEST_CASE("render command: a collider placed by $OBJID and $NOBJ is drawn where it was simulated",
          "[viewer]") {
  const std::string dir = test::temp_dir("render_objects");
  const std::string graph = test::write_file(dir, "g.json", kPerObjectGraph);
  const std::string sim = dir + "/sim", log = dir + "/log.txt";
  REQUIRE(test::run_grains("run " + graph + " --out " + sim + " --quiet", log) == 0);

  // the poses the run wrote are the ones the simulation used, bit for bit
  Simulation s(test::graph_from(kPerObjectGraph), 1);
  std::vector<std::vector<ColliderState>> used(3);  // frame -> every object's colliders
  for (int f = 1; f <= 2; ++f) {
    s.step_frame();
    for (size_t k = 0; k < s.object_count(); ++k) {
      const SimObject& o = s.object(k);
      const auto written = read_collider_poses(sim + "/" + o.name + "/" + kColliderPosesFile);
      REQUIRE(written.count(f));
      REQUIRE(written.at(f).size() == o.colliders.size());
      for (size_t c = 0; c < o.colliders.size(); ++c) {
        INFO("frame " << f << ", solver " << o.name << ", collider " << o.colliders[c].name);
        CHECK(same_pose(written.at(f)[c], o.colliders[c]));
      }
      used[f].insert(used[f].end(), o.colliders.begin(), o.colliders.end());
    }
  }
  // solver b met the ball at OBJID 1, NOBJ 2
  const ColliderState& ball_b = used[2].back();
  REQUIRE(ball_b.name == "ball");
  CHECK(ball_b.pose.t.x == Approx(0.25));
  CHECK(ball_b.pose.t.y == Approx(0.5 + 2 / 24.0));

  // the rendered frame is the one drawn from the simulation's own poses
  RenderOptions o;
  o.dir = sim;
  o.out = dir + "/pictures";
  o.size = "96x64";
  o.supersample = 1;
  o.quiet = true;
  o.camera = "0,0.3,2.5,0,0.3,0,40";
  REQUIRE(render_command(o) == 0);
  const Camera cam = Camera::look_at({0, 0.3f, 2.5f}, {0, 0.3f, 0}, 40, 96, 64);
  RenderSettings settings;
  settings.supersample = 1;
  ParticleStore pa = read_ply(sim + "/a/frame_0002.ply"), pb = read_ply(sim + "/b/frame_0002.ply");
  Image expected = render_frame({&pa, &pb}, cam, settings, used[2]);
  char caption[96];
  std::snprintf(caption, sizeof caption, "frame %d  t %.3f s  %zu grains", 2, 2 / 24.0,
                pa.size() + pb.size());
  draw_caption(expected, caption);
  const std::optional<test::Png> png = test::read_png(o.out + "/frame_0002.png");
  REQUIRE(png);
  REQUIRE(png->w == 96);
  REQUIRE(png->h == 64);
  CHECK(std::equal(expected.rgb.begin(), expected.rgb.end(), png->rgb.begin()));
  // and not the one a viewer evaluating the graph for itself drew (OBJID 0, NOBJ 1 for every
  // object): there, solver b's ball was missing
  std::vector<ColliderState> object_a_only(used[2].begin(), used[2].begin() + 2);
  Image wrong = render_frame({&pa, &pb}, cam, settings, object_a_only);
  draw_caption(wrong, caption);
  CHECK_FALSE(wrong.rgb == expected.rgb);
}

TEST_CASE("render command: a missing or damaged collider_poses.csv warns or is refused, no crash",
          "[viewer]") {
  const std::string dir = test::temp_dir("render_poses");
  const std::string graph = test::write_file(dir, "g.json", kPerObjectGraph);
  const std::string sim = dir + "/sim", log = dir + "/log.txt", pics = " --out " + dir + "/p";
  REQUIRE(test::run_grains("run " + graph + " --out " + sim + " --quiet", log) == 0);
  const std::string poses_b = sim + "/b/" + kColliderPosesFile;
  const std::string text_b = test::read_text(poses_b);

  SECTION("missing: drawn without that solver's colliders and a warning; refused with --graph") {
    std::filesystem::remove(poses_b);
    CHECK(test::run_grains("render " + sim + pics + " --size 32x24 --quiet", log) == 0);
    CHECK_THAT(test::read_text(log),
               Catch::Contains("grains render: warning: " + poses_b + " does not exist") &&
                   Catch::Contains("its colliders are not drawn"));
    CHECK(std::filesystem::exists(dir + "/p/frame_0002.png"));
    CHECK(test::run_grains("render " + sim + pics + " --size 32x24 --graph " + graph, log) == 2);
    CHECK_THAT(test::read_text(log), Catch::Contains("grains render: error: --graph " + graph) &&
                                         Catch::Contains(poses_b + " does not exist"));
  }
  SECTION("a frame without rows: drawn without colliders and a warning") {
    test::write_file(sim + "/b", kColliderPosesFile, text_b.substr(0, text_b.rfind("\n2,") + 1));
    CHECK(test::run_grains("render " + sim + pics + " --size 32x24 --quiet", log) == 0);
    CHECK_THAT(test::read_text(log), Catch::Contains("grains render: warning: " +
                                                     std::string(kColliderPosesFile) +
                                                     " has no collider poses for frame 2"));
  }
  SECTION("damaged: refused with the file, the line and what is wrong") {
    for (const std::string& bad :
         {text_b + "3,0.125,ball,sphere,nan\n", text_b.substr(0, text_b.size() / 2),
          std::string("\x01\x02 not text at all"), std::string()}) {
      test::write_file(sim + "/b", kColliderPosesFile, bad);
      INFO(bad);
      CHECK(test::run_grains("render " + sim + pics + " --size 32x24 --quiet", log) == 2);
      CHECK_THAT(test::read_text(log), Catch::Contains("grains render: error: " + poses_b + ":"));
    }
  }
}

TEST_CASE("render time for 100,000 grains", "[.][viewer][bench]") {
  // hidden (run with "[bench]"): a settled-looking pile of 100k grains at 960x540; reports the
  // time, asserts none (speed lives in benchmarks)
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Vec3> c;
  std::vector<float> r;
  for (int i = 0; i < 100000; ++i) {
    float a = u(rng) * 2 * static_cast<float>(M_PI), d = std::sqrt(u(rng));
    float h = u(rng) * (1 - d) * 0.6f;
    c.push_back({d * std::cos(a), h, d * std::sin(a)});
    r.push_back(0.008f);
  }
  ParticleStore p = spheres(c, r);
  Bounds b;
  for (auto& x : c) b.add(x, 0.008f);
  Camera cam = frame_bounds(b, 960, 540);
  ColliderState ground;
  for (int ss : {1, 2}) {
    RenderSettings s;
    s.supersample = ss;
    s.scene = b;
    render_frame(p, cam, s, {ground});  // warm up
    auto t0 = std::chrono::steady_clock::now();
    const int reps = 3;
    Image img;
    for (int k = 0; k < reps; ++k) img = render_frame(p, cam, s, {ground});
    double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() /
        reps;
    WARN("100k grains, 960x540, supersample " << ss << ", " << omp_get_max_threads()
                                              << " threads: " << ms << " ms");
    auto t1 = std::chrono::steady_clock::now();
    write_png(test::temp_dir("bench") + "/f.png", img);
    double png_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count();
    WARN("  PNG write: " << png_ms << " ms");
  }
}
