// Pinhole camera and automatic framing for the offline viewer.
#include <algorithm>
#include <cmath>

#include "viewer-offline/render.h"

namespace grains::viewer {

void Bounds::add(const Vec3& p, float r) {
  if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || !std::isfinite(r))
    return;
  r = std::max(r, 0.0f);
  lo = {std::min(lo.x, p.x - r), std::min(lo.y, p.y - r), std::min(lo.z, p.z - r)};
  hi = {std::max(hi.x, p.x + r), std::max(hi.y, p.y + r), std::max(hi.z, p.z + r)};
}

void Bounds::add(const Bounds& b) {
  if (!b.valid()) return;
  add(b.lo);
  add(b.hi);
}

Camera Camera::look_at(const Vec3& eye, const Vec3& target, float fov_deg, int width, int height) {
  Camera c;
  c.eye = eye;
  c.target = target;
  c.fov_deg = fov_deg;
  c.width = width;
  c.height = height;
  Vec3 f = normalized(target - eye);
  if (length(f) == 0) f = {0, 0, -1};
  // world +y is up unless we look (almost) straight along it
  Vec3 up_hint = std::fabs(f.y) > 0.999f ? Vec3{0, 0, f.y > 0 ? 1.0f : -1.0f} : Vec3{0, 1, 0};
  c.forward = f;
  c.right = normalized(cross(f, up_hint));
  c.up = cross(c.right, f);
  const double half = 0.5 * fov_deg * M_PI / 180.0;
  c.focal = static_cast<float>(0.5 * height / std::tan(half));
  return c;
}

bool Camera::project(const Vec3& p, float* px, float* py, float* depth) const {
  Vec3 c = to_camera(p);
  if (depth) *depth = c.z;
  if (!(c.z > 1e-6f)) return false;
  if (px) *px = 0.5f * width + focal * c.x / c.z;
  if (py) *py = 0.5f * height - focal * c.y / c.z;
  return true;
}

Camera Camera::scaled(int factor) const {
  Camera c = *this;
  c.width = width * factor;
  c.height = height * factor;
  c.focal = focal * factor;
  return c;
}

Camera frame_bounds(const Bounds& box_in, int width, int height, float fov_deg, float azimuth_deg,
                    float elevation_deg) {
  Bounds box = box_in;
  if (!box.valid()) box.add(Vec3{0, 0, 0}, 0.5f);
  // a flat or point-like box still gets a sensible distance
  Vec3 c0 = box.center(), s = box.size();
  float min_size = std::max(0.05f, 0.05f * std::max({s.x, s.y, s.z}));
  box.add(c0, 0.5f * min_size);

  const double az = azimuth_deg * M_PI / 180.0, el = elevation_deg * M_PI / 180.0;
  Vec3 back{static_cast<float>(std::cos(el) * std::sin(az)), static_cast<float>(std::sin(el)),
            static_cast<float>(std::cos(el) * std::cos(az))};
  const float tan_v = static_cast<float>(std::tan(0.5 * fov_deg * M_PI / 180.0));
  const float tan_h = tan_v * static_cast<float>(width) / static_cast<float>(height);
  const float fill = 0.9f;  // corners reach 90% of the half-frame

  Vec3 corners[8];
  for (int k = 0; k < 8; ++k)
    corners[k] = {(k & 1) ? box.hi.x : box.lo.x, (k & 2) ? box.hi.y : box.lo.y,
                  (k & 4) ? box.hi.z : box.lo.z};

  Vec3 target = box.center();
  Camera cam = Camera::look_at(target + back, target, fov_deg, width, height);
  // the smallest distance from target at which every corner fits
  auto fit_distance = [&](const Vec3& target, const Camera& cam) {
    float D = 0;
    for (const Vec3& c : corners) {
      Vec3 r = c - target;
      float x = dot(r, cam.right), y = dot(r, cam.up), z = dot(r, cam.forward);
      D = std::max(D, std::fabs(x) / (fill * tan_h) - z);
      D = std::max(D, std::fabs(y) / (fill * tan_v) - z);
    }
    return D;
  };
  // then recentre the corners' projection on the frame; a few rounds converge
  for (int round = 0; round < 4; ++round) {
    float D = fit_distance(target, cam);
    float xmin = 1e30f, xmax = -1e30f, ymin = 1e30f, ymax = -1e30f;
    for (const Vec3& c : corners) {
      Vec3 r = c - target;
      float depth = D + dot(r, cam.forward);
      float x = dot(r, cam.right) / depth / tan_h, y = dot(r, cam.up) / depth / tan_v;
      xmin = std::min(xmin, x);
      xmax = std::max(xmax, x);
      ymin = std::min(ymin, y);
      ymax = std::max(ymax, y);
    }
    target += cam.right * (0.5f * (xmin + xmax) * tan_h * D) +
              cam.up * (0.5f * (ymin + ymax) * tan_v * D);
    cam = Camera::look_at(target + back, target, fov_deg, width, height);
  }
  return Camera::look_at(target + back * fit_distance(target, cam), target, fov_deg, width, height);
}

}  // namespace grains::viewer
