// PNG files read back by tests (the viewer's renders and plots), through stb_image, which is
// compiled once for the test binary, in png.cpp.
#pragma once
#include <optional>
#include <string>
#include <vector>

namespace grains::test {

// A PNG decoded to 8-bit RGB.
struct Png {
  int w = 0, h = 0;
  std::vector<unsigned char> rgb;  // (h x w x 3), rows from the top
  // The pixel at column x, row y: three bytes r g b.
  const unsigned char* at(int x, int y) const { return rgb.data() + 3 * (size_t(y) * w + x); }
};

// Decodes PATH; nothing when it is not an image stb_image reads.
std::optional<Png> read_png(const std::string& path);
// PATH's size from its header, without decoding; false when it is not an image stb_image reads.
bool png_size(const std::string& path, int* w, int* h);

}  // namespace grains::test
