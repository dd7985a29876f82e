#include "viewer-offline/image.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

// stb_image_write's implementation lives here, with static linkage so that no other copy in the
// program can clash with it; its own warnings are not ours.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>
#pragma GCC diagnostic pop

namespace grains::viewer {

uint8_t to_byte(float v) {
  if (!(v > 0)) return 0;  // NaN too
  if (v >= 1) return 255;
  return static_cast<uint8_t>(v * 255.0f + 0.5f);
}

Image::Image(int w, int h) : width(w), height(h), rgb(static_cast<size_t>(w) * h * 3, 0) {}

void Image::set(int x, int y, const Rgb& c) {
  uint8_t* p = px(x, y);
  p[0] = to_byte(c.r);
  p[1] = to_byte(c.g);
  p[2] = to_byte(c.b);
}

Rgb Image::get(int x, int y) const {
  const uint8_t* p = px(x, y);
  return {p[0] / 255.0f, p[1] / 255.0f, p[2] / 255.0f};
}

void Image::blend(int x, int y, const Rgb& c, float alpha) {
  if (!inside(x, y) || !(alpha > 0)) return;
  if (alpha >= 1) {
    set(x, y, c);
    return;
  }
  set(x, y, mix(get(x, y), c, alpha));
}

void Image::fill_rect(int x0, int y0, int x1, int y1, const Rgb& c, float alpha) {
  x0 = std::max(x0, 0);
  y0 = std::max(y0, 0);
  x1 = std::min(x1, width);
  y1 = std::min(y1, height);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) blend(x, y, c, alpha);
}

void Image::paste(const Image& src, int x, int y) {
  for (int j = 0; j < src.height; ++j) {
    if (y + j < 0 || y + j >= height) continue;
    for (int i = 0; i < src.width; ++i) {
      if (x + i < 0 || x + i >= width) continue;
      const uint8_t* s = src.px(i, j);
      uint8_t* d = px(x + i, y + j);
      d[0] = s[0];
      d[1] = s[1];
      d[2] = s[2];
    }
  }
}

Image downscale(const Image& src, int factor) {
  if (factor <= 1) return src;
  Image out(src.width / factor, src.height / factor);
  bool has_depth = !src.depth.empty();
  if (has_depth) out.depth.assign(static_cast<size_t>(out.width) * out.height, 0);
  const int n = factor * factor;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x) {
      int sum[3] = {0, 0, 0};
      float zmin = std::numeric_limits<float>::infinity();
      for (int j = 0; j < factor; ++j)
        for (int i = 0; i < factor; ++i) {
          int sx = x * factor + i, sy = y * factor + j;
          const uint8_t* p = src.px(sx, sy);
          sum[0] += p[0];
          sum[1] += p[1];
          sum[2] += p[2];
          if (has_depth) zmin = std::min(zmin, src.depth[static_cast<size_t>(sy) * src.width + sx]);
        }
      uint8_t* d = out.px(x, y);
      for (int c = 0; c < 3; ++c) d[c] = static_cast<uint8_t>((sum[c] + n / 2) / n);
      if (has_depth) out.depth[static_cast<size_t>(y) * out.width + x] = zmin;
    }
  return out;
}

Image resize(const Image& src, int w, int h) {
  Image out(std::max(w, 1), std::max(h, 1));
  const double sx = static_cast<double>(src.width) / out.width;
  const double sy = static_cast<double>(src.height) / out.height;
  for (int y = 0; y < out.height; ++y) {
    double y0 = y * sy, y1 = (y + 1) * sy;
    for (int x = 0; x < out.width; ++x) {
      double x0 = x * sx, x1 = (x + 1) * sx;
      double acc[3] = {0, 0, 0}, wsum = 0;
      // each source pixel weighs by its overlap with the destination pixel's footprint
      for (int j = static_cast<int>(y0); j < std::min(src.height, static_cast<int>(std::ceil(y1)));
           ++j) {
        double wy = std::min(y1, j + 1.0) - std::max(y0, static_cast<double>(j));
        if (wy <= 0) continue;
        for (int i = static_cast<int>(x0); i < std::min(src.width, static_cast<int>(std::ceil(x1)));
             ++i) {
          double wx = std::min(x1, i + 1.0) - std::max(x0, static_cast<double>(i));
          if (wx <= 0) continue;
          const uint8_t* p = src.px(i, j);
          for (int c = 0; c < 3; ++c) acc[c] += wx * wy * p[c];
          wsum += wx * wy;
        }
      }
      uint8_t* d = out.px(x, y);
      for (int c = 0; c < 3; ++c)
        d[c] = static_cast<uint8_t>(std::clamp(acc[c] / std::max(wsum, 1e-12) + 0.5, 0.0, 255.0));
    }
  }
  return out;
}

void write_png(const std::string& path, const Image& img) {
  if (img.width <= 0 || img.height <= 0) throw std::runtime_error(path + ": empty image");
  // level 4 writes a 960x540 frame about three times faster than the default 8, files ~10% larger
  stbi_write_png_compression_level = 4;
  if (!stbi_write_png(path.c_str(), img.width, img.height, 3, img.rgb.data(), img.width * 3))
    throw std::runtime_error(path + ": cannot write PNG");
}

// ---- the built-in font ----------------------------------------------------------------------

namespace {

struct Glyph {
  char c;
  const char* rows[7];  // '#' = ink, 5 columns
};

// clang-format off
const Glyph kGlyphs[] = {
    {'0', {" ### ", "#   #", "#  ##", "# # #", "##  #", "#   #", " ### "}},
    {'1', {"  #  ", " ##  ", "  #  ", "  #  ", "  #  ", "  #  ", " ### "}},
    {'2', {" ### ", "#   #", "    #", "   # ", "  #  ", " #   ", "#####"}},
    {'3', {"#####", "   # ", "  #  ", "   # ", "    #", "#   #", " ### "}},
    {'4', {"   # ", "  ## ", " # # ", "#  # ", "#####", "   # ", "   # "}},
    {'5', {"#####", "#    ", "#### ", "    #", "    #", "#   #", " ### "}},
    {'6', {"  ## ", " #   ", "#    ", "#### ", "#   #", "#   #", " ### "}},
    {'7', {"#####", "    #", "   # ", "  #  ", " #   ", " #   ", " #   "}},
    {'8', {" ### ", "#   #", "#   #", " ### ", "#   #", "#   #", " ### "}},
    {'9', {" ### ", "#   #", "#   #", " ####", "    #", "   # ", " ##  "}},
    {'A', {" ### ", "#   #", "#   #", "#####", "#   #", "#   #", "#   #"}},
    {'B', {"#### ", "#   #", "#   #", "#### ", "#   #", "#   #", "#### "}},
    {'C', {" ### ", "#   #", "#    ", "#    ", "#    ", "#   #", " ### "}},
    {'D', {"###  ", "#  # ", "#   #", "#   #", "#   #", "#  # ", "###  "}},
    {'E', {"#####", "#    ", "#    ", "#### ", "#    ", "#    ", "#####"}},
    {'F', {"#####", "#    ", "#    ", "#### ", "#    ", "#    ", "#    "}},
    {'G', {" ### ", "#   #", "#    ", "# ###", "#   #", "#   #", " ####"}},
    {'H', {"#   #", "#   #", "#   #", "#####", "#   #", "#   #", "#   #"}},
    {'I', {" ### ", "  #  ", "  #  ", "  #  ", "  #  ", "  #  ", " ### "}},
    {'J', {"  ###", "   # ", "   # ", "   # ", "   # ", "#  # ", " ##  "}},
    {'K', {"#   #", "#  # ", "# #  ", "##   ", "# #  ", "#  # ", "#   #"}},
    {'L', {"#    ", "#    ", "#    ", "#    ", "#    ", "#    ", "#####"}},
    {'M', {"#   #", "## ##", "# # #", "# # #", "#   #", "#   #", "#   #"}},
    {'N', {"#   #", "#   #", "##  #", "# # #", "#  ##", "#   #", "#   #"}},
    {'O', {" ### ", "#   #", "#   #", "#   #", "#   #", "#   #", " ### "}},
    {'P', {"#### ", "#   #", "#   #", "#### ", "#    ", "#    ", "#    "}},
    {'Q', {" ### ", "#   #", "#   #", "#   #", "# # #", "#  # ", " ## #"}},
    {'R', {"#### ", "#   #", "#   #", "#### ", "# #  ", "#  # ", "#   #"}},
    {'S', {" ####", "#    ", "#    ", " ### ", "    #", "    #", "#### "}},
    {'T', {"#####", "  #  ", "  #  ", "  #  ", "  #  ", "  #  ", "  #  "}},
    {'U', {"#   #", "#   #", "#   #", "#   #", "#   #", "#   #", " ### "}},
    {'V', {"#   #", "#   #", "#   #", "#   #", "#   #", " # # ", "  #  "}},
    {'W', {"#   #", "#   #", "#   #", "# # #", "# # #", "# # #", " # # "}},
    {'X', {"#   #", "#   #", " # # ", "  #  ", " # # ", "#   #", "#   #"}},
    {'Y', {"#   #", "#   #", " # # ", "  #  ", "  #  ", "  #  ", "  #  "}},
    {'Z', {"#####", "    #", "   # ", "  #  ", " #   ", "#    ", "#####"}},
    {'.', {"     ", "     ", "     ", "     ", "     ", " ##  ", " ##  "}},
    {',', {"     ", "     ", "     ", "     ", " ##  ", "  #  ", " #   "}},
    {'-', {"     ", "     ", "     ", "#####", "     ", "     ", "     "}},
    {'+', {"     ", "  #  ", "  #  ", "#####", "  #  ", "  #  ", "     "}},
    {'_', {"     ", "     ", "     ", "     ", "     ", "     ", "#####"}},
    {':', {"     ", " ##  ", " ##  ", "     ", " ##  ", " ##  ", "     "}},
    {'=', {"     ", "     ", "#####", "     ", "#####", "     ", "     "}},
    {'/', {"     ", "    #", "   # ", "  #  ", " #   ", "#    ", "     "}},
    {'(', {"   # ", "  #  ", " #   ", " #   ", " #   ", "  #  ", "   # "}},
    {')', {" #   ", "  #  ", "   # ", "   # ", "   # ", "  #  ", " #   "}},
    {'[', {" ### ", " #   ", " #   ", " #   ", " #   ", " #   ", " ### "}},
    {']', {" ### ", "   # ", "   # ", "   # ", "   # ", "   # ", " ### "}},
    {'%', {"##   ", "##  #", "   # ", "  #  ", " #   ", "#  ##", "   ##"}},
    {'<', {"   # ", "  #  ", " #   ", "#    ", " #   ", "  #  ", "   # "}},
    {'>', {" #   ", "  #  ", "   # ", "    #", "   # ", "  #  ", " #   "}},
    {'|', {"  #  ", "  #  ", "  #  ", "  #  ", "  #  ", "  #  ", "  #  "}},
    {'#', {" # # ", " # # ", "#####", " # # ", "#####", " # # ", " # # "}},
    {' ', {"     ", "     ", "     ", "     ", "     ", "     ", "     "}},
};
const Glyph kUnknown = {'?', {"     ", "#####", "#   #", "#   #", "#   #", "#####", "     "}};
// clang-format on

const Glyph& glyph_for(char c) {
  if (c >= 'a' && c <= 'z') c = static_cast<char>(c - 'a' + 'A');
  for (const Glyph& g : kGlyphs)
    if (g.c == c) return g;
  return kUnknown;
}

}  // namespace

int text_width(const std::string& s, int scale) {
  return s.empty() ? 0 : (static_cast<int>(s.size()) * 6 - 1) * scale;
}

void draw_text(Image& img, int x, int y, const std::string& s, const Rgb& color, int scale) {
  for (size_t k = 0; k < s.size(); ++k) {
    const Glyph& g = glyph_for(s[k]);
    int gx = x + static_cast<int>(k) * 6 * scale;
    for (int row = 0; row < 7; ++row)
      for (int col = 0; col < 5; ++col)
        if (g.rows[row][col] == '#')
          img.fill_rect(gx + col * scale, y + row * scale, gx + (col + 1) * scale,
                        y + (row + 1) * scale, color);
  }
}

void draw_text_up(Image& img, int x, int y, const std::string& s, const Rgb& color, int scale) {
  for (size_t k = 0; k < s.size(); ++k) {
    const Glyph& g = glyph_for(s[k]);
    int gu = static_cast<int>(k) * 6 * scale;  // along the text, upwards from y
    for (int row = 0; row < 7; ++row)
      for (int col = 0; col < 5; ++col)
        if (g.rows[row][col] == '#') {
          int u = gu + col * scale;
          img.fill_rect(x + row * scale, y - u - scale + 1, x + (row + 1) * scale, y - u + 1,
                        color);
        }
  }
}

// ---- plot strokes -----------------------------------------------------------------------------

void draw_line(Image& img, double x0, double y0, double x1, double y1, const Rgb& color,
               int thick) {
  int n = static_cast<int>(std::ceil(std::max(std::fabs(x1 - x0), std::fabs(y1 - y0)))) + 1;
  int lo = -(thick - 1) / 2, hi = thick / 2;
  for (int k = 0; k <= n; ++k) {
    double t = double(k) / n;
    int x = static_cast<int>(std::lround(x0 + (x1 - x0) * t));
    int y = static_cast<int>(std::lround(y0 + (y1 - y0) * t));
    img.fill_rect(x + lo, y + lo, x + hi + 1, y + hi + 1, color);
  }
}

void draw_disc(Image& img, double cx, double cy, double r, const Rgb& color, bool filled) {
  for (int y = int(cy - r - 1); y <= int(cy + r + 1); ++y)
    for (int x = int(cx - r - 1); x <= int(cx + r + 1); ++x) {
      double d = std::hypot(x - cx, y - cy);
      if (img.inside(x, y) && (filled ? d <= r : (d <= r && d >= r - 1.6))) img.set(x, y, color);
    }
}

}  // namespace grains::viewer
