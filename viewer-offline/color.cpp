// Colouring by attribute: per-point or per-edge values, the colour ramp and the colour bar.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "viewer-offline/render.h"

namespace grains::viewer {

AttribDomain attribute_values(const ParticleStore& pts, const std::string& attr_in,
                              std::vector<float>& out) {
  out.clear();
  std::string attr = attr_in;
  int component = -1;  // NAME.x / .y / .z
  if (attr.size() > 2 && attr[attr.size() - 2] == '.') {
    char c = attr.back();
    if (c == 'x' || c == 'y' || c == 'z') {
      component = c - 'x';
      attr.resize(attr.size() - 2);
    }
  }
  if (const Attribute* a = pts.find(attr)) {
    const size_t n = pts.size();
    out.resize(n);
    switch (a->type) {
      case AttribType::Float:
        for (size_t i = 0; i < n; ++i) out[i] = a->f[i];
        break;
      case AttribType::Int:
        for (size_t i = 0; i < n; ++i) out[i] = static_cast<float>(a->i[i]);
        break;
      case AttribType::Vec3:
        for (size_t i = 0; i < n; ++i) {
          Vec3 v = load3(a->f.data(), i);
          out[i] = component >= 0 ? v[component] : length(v);
        }
        break;
    }
    if (component >= 0 && a->type != AttribType::Vec3) {  // "name.x" of a scalar: no such thing
      out.clear();
      return AttribDomain::None;
    }
    return AttribDomain::Point;
  }
  if (component < 0)
    if (const float* e = pts.prim_f_if(attr)) {
      out.assign(e, e + pts.prim_count());
      return AttribDomain::Edge;
    }
  return AttribDomain::None;
}

Rgb colormap(float t) {
  // viridis sampled at tenths (matplotlib), interpolated linearly
  static const Rgb kRamp[11] = {
      {0.267f, 0.005f, 0.329f}, {0.282f, 0.141f, 0.459f}, {0.255f, 0.267f, 0.530f},
      {0.208f, 0.373f, 0.553f}, {0.165f, 0.471f, 0.557f}, {0.129f, 0.569f, 0.549f},
      {0.133f, 0.659f, 0.518f}, {0.267f, 0.749f, 0.439f}, {0.478f, 0.820f, 0.318f},
      {0.741f, 0.874f, 0.150f}, {0.992f, 0.906f, 0.145f}};
  if (!(t > 0)) return kRamp[0];
  if (t >= 1) return kRamp[10];
  float x = t * 10;
  int k = std::min(static_cast<int>(x), 9);
  return mix(kRamp[k], kRamp[k + 1], x - k);
}

float ColorBy::t(float value) const {
  float span = max - min;
  if (!(span > 0)) return 0.5f;
  return std::clamp((value - min) / span, 0.0f, 1.0f);
}

std::string format_value(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

namespace {
int text_scale(int height) {
  return height >= 400 ? 2 : 1;
}
}  // namespace

Rect color_bar_rect(int width, int height) {
  Rect r;
  int bw = std::max(6, width / 60);
  int bh = std::max(8, height / 2);
  r.x1 = width - std::max(8, width / 40);
  r.x0 = r.x1 - bw;
  r.y0 = (height - bh) / 2 + text_height(text_scale(height));
  r.y1 = std::min(height, r.y0 + bh);
  return r;
}

void draw_color_bar(Image& img, const ColorBy& c) {
  const Rect r = color_bar_rect(img.width, img.height);
  const int s = text_scale(img.height);
  const int th = text_height(s), pad = 3 * s;
  std::string hi = format_value(c.max), lo = format_value(c.min);
  int label_w = std::max(text_width(hi, s), text_width(lo, s));
  int name_w = text_width(c.attribute, s);
  // a light panel keeps labels readable over grains
  int panel_x0 = std::min(r.x0 - pad - label_w - pad, r.x1 - name_w - pad);
  img.fill_rect(panel_x0, r.y0 - th - 3 * pad, r.x1 + pad, r.y1 + pad, Rgb{1, 1, 1}, 0.6f);
  const int rows = r.y1 - r.y0;
  for (int y = r.y0; y < r.y1; ++y) {
    float t = rows > 1 ? static_cast<float>(r.y1 - 1 - y) / static_cast<float>(rows - 1) : 0.0f;
    Rgb col = colormap(t);
    for (int x = r.x0; x < r.x1; ++x)
      if (img.inside(x, y)) img.set(x, y, col);
  }
  const Rgb ink{0.1f, 0.1f, 0.1f};
  draw_text(img, r.x0 - pad - text_width(hi, s), r.y0, hi, ink, s);
  draw_text(img, r.x0 - pad - text_width(lo, s), r.y1 - th, lo, ink, s);
  draw_text(img, r.x1 - name_w, r.y0 - th - 2 * pad, c.attribute, ink, s);
}

}  // namespace grains::viewer
