#include "tests/support/png.h"

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#include <stb_image.h>
#pragma GCC diagnostic pop

namespace grains::test {

std::optional<Png> read_png(const std::string& path) {
  Png png;
  int n = 0;
  unsigned char* data = stbi_load(path.c_str(), &png.w, &png.h, &n, 3);
  if (!data) return std::nullopt;
  png.rgb.assign(data, data + size_t(3) * png.w * png.h);
  stbi_image_free(data);
  return png;
}

bool png_size(const std::string& path, int* w, int* h) {
  int n = 0;
  return stbi_info(path.c_str(), w, h, &n) == 1;
}

}  // namespace grains::test
