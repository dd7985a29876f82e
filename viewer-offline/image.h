// RGB images for the offline viewer and the lab's plots (lab/bench.cpp): 8-bit pixels stored row
// by row from the top, an optional depth channel, box-filter scaling, PNG writing, lines and discs,
// and a tiny built-in 5x7 bitmap font for labels. The program's one PNG writer.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace grains::viewer {

// A display colour, each channel in [0, 1] (sRGB-encoded values, written as bytes directly).
struct Rgb {
  float r = 0, g = 0, b = 0;
};
inline Rgb operator*(const Rgb& c, float s) {
  return {c.r * s, c.g * s, c.b * s};
}
inline Rgb operator+(const Rgb& a, const Rgb& b) {
  return {a.r + b.r, a.g + b.g, a.b + b.b};
}
inline Rgb mix(const Rgb& a, const Rgb& b, float t) {
  return a * (1 - t) + b * t;
}

// [0, 1] → byte, clamped and rounded.
uint8_t to_byte(float v);

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // (height x width x 3), row 0 at the top
  std::vector<float>
      depth;  // (height x width) camera-space z (m), +inf where nothing; may be empty

  Image() = default;
  Image(int w, int h);  // black, no depth channel

  bool inside(int x, int y) const { return x >= 0 && y >= 0 && x < width && y < height; }
  uint8_t* px(int x, int y) { return &rgb[3 * (static_cast<size_t>(y) * width + x)]; }
  const uint8_t* px(int x, int y) const { return &rgb[3 * (static_cast<size_t>(y) * width + x)]; }
  void set(int x, int y, const Rgb& c);
  Rgb get(int x, int y) const;
  // c over the pixel with opacity alpha in [0, 1]; ignores pixels outside the image
  void blend(int x, int y, const Rgb& c, float alpha);
  // [x0, x1) x [y0, y1), clipped to the image
  void fill_rect(int x0, int y0, int x1, int y1, const Rgb& c, float alpha = 1);
  // copies src with its top-left corner at (x, y), clipped
  void paste(const Image& src, int x, int y);
};

// Averages factor x factor blocks (width and height divided, rounding down). The depth channel,
// if any, keeps the nearest depth of each block.
Image downscale(const Image& src, int factor);
// Area-averaging resize to w x h (for thumbnails); drops the depth channel.
Image resize(const Image& src, int w, int h);

// Writes an 8-bit RGB PNG. Throws std::runtime_error naming the file on failure.
void write_png(const std::string& path, const Image& img);

// The built-in font: 5 x 7 pixel glyphs on a 6-pixel advance, drawn `scale` times larger.
// It knows digits, letters (lower case drawn as upper case) and . , - + _ : = / ( ) % < > | [ ] #
// and space; anything else draws as a small box.
int text_width(const std::string& s, int scale);
inline int text_height(int scale) {
  return 7 * scale;
}
// Draws s with its top-left corner at (x, y).
void draw_text(Image& img, int x, int y, const std::string& s, const Rgb& color, int scale);
// Draws s turned a quarter left, reading bottom to top, from (x, y) up (an axis label).
void draw_text_up(Image& img, int x, int y, const std::string& s, const Rgb& color, int scale);

// Plot strokes: a line `thick` pixels wide from (x0, y0) to (x1, y1), one square of pixels per
// step of the longer axis; a disc of radius r around (cx, cy), or only its rim (1.6 px wide).
void draw_line(Image& img, double x0, double y0, double x1, double y1, const Rgb& color,
               int thick = 1);
void draw_disc(Image& img, double cx, double cy, double r, const Rgb& color, bool filled = true);

}  // namespace grains::viewer
