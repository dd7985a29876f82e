// A small animated-GIF writer (GIF89a, looping), for videos when ffmpeg is not installed.
// One fixed 256-colour palette for every frame: a 6 x 7 x 6 RGB cube (green, to which the eye is
// most sensitive, gets 7 levels) plus 4 greys, with 4x4 ordered (Bayer) dithering; LZW-coded
// with the usual 9-to-12-bit variable code size and a clear code when the table fills.
#pragma once
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "viewer-offline/image.h"

namespace grains::viewer {

// The fixed palette, 256 x (r, g, b).
const std::vector<uint8_t>& gif_palette();
// Palette index of a colour at pixel (x, y) (the dither pattern depends on the position).
// Colours exactly on the cube's levels map to themselves.
uint8_t gif_palette_index(uint8_t r, uint8_t g, uint8_t b, int x, int y);

class GifWriter {
 public:
  // Opens `path` and writes the header; delay between frames in 1/100 s. Throws
  // std::runtime_error naming the file when it cannot be written.
  GifWriter(const std::string& path, int width, int height, int delay_cs);
  ~GifWriter();
  GifWriter(const GifWriter&) = delete;
  GifWriter& operator=(const GifWriter&) = delete;

  // Appends a frame; the image must have the size given at construction.
  void add_frame(const Image& img);
  // Writes the trailer and closes the file (also done by the destructor). Throws on write errors.
  void close();

 private:
  std::string path_;
  std::FILE* f_ = nullptr;
  int width_, height_, delay_cs_;
};

}  // namespace grains::viewer
