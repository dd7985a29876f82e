// The contact sheet: evenly spaced frames shrunk 4x in a grid, each with its frame number.
#include <algorithm>
#include <cmath>
#include <string>

#include "viewer-offline/render.h"

namespace grains::viewer {

ContactSheetLayout contact_sheet_layout(int count, int frame_width, int frame_height) {
  ContactSheetLayout l;
  if (count <= 0) return l;
  l.columns = std::min(count, 4);
  l.rows = (count + l.columns - 1) / l.columns;
  l.thumb_width = std::max(1, frame_width / 4);
  l.thumb_height = std::max(1, frame_height / 4);
  l.width = l.columns * l.thumb_width + (l.columns + 1) * l.gap;
  l.height = l.rows * l.thumb_height + (l.rows + 1) * l.gap;
  return l;
}

std::vector<int> contact_sheet_picks(int count, int max_thumbs) {
  std::vector<int> picks;
  if (count <= 0 || max_thumbs <= 0) return picks;
  if (count <= max_thumbs || max_thumbs == 1) {
    for (int k = 0; k < std::min(count, max_thumbs); ++k) picks.push_back(k);
    return picks;
  }
  for (int k = 0; k < max_thumbs; ++k)
    picks.push_back(
        static_cast<int>(std::lround(static_cast<double>(k) * (count - 1) / (max_thumbs - 1))));
  return picks;
}

Image contact_sheet(const std::vector<Image>& frames, const std::vector<int>& frame_numbers,
                    int frame_width, int frame_height) {
  if (frames.empty()) return Image();
  ContactSheetLayout l =
      contact_sheet_layout(static_cast<int>(frames.size()), frame_width, frame_height);
  Image sheet(l.width, l.height);
  sheet.fill_rect(0, 0, l.width, l.height, Rgb{0.22f, 0.22f, 0.23f});
  for (size_t k = 0; k < frames.size(); ++k) {
    int col = static_cast<int>(k) % l.columns, row = static_cast<int>(k) / l.columns;
    int x = l.gap + col * (l.thumb_width + l.gap), y = l.gap + row * (l.thumb_height + l.gap);
    const Image& f = frames[k];
    if (f.width == l.thumb_width && f.height == l.thumb_height)
      sheet.paste(f, x, y);
    else
      sheet.paste(resize(f, l.thumb_width, l.thumb_height), x, y);
    if (k < frame_numbers.size()) {
      std::string label = std::to_string(frame_numbers[k]);
      int s = l.thumb_height >= 100 ? 2 : 1;
      sheet.fill_rect(x, y, x + text_width(label, s) + 4 * s, y + text_height(s) + 4 * s,
                      Rgb{1, 1, 1}, 0.7f);
      draw_text(sheet, x + 2 * s, y + 2 * s, label, Rgb{0.1f, 0.1f, 0.1f}, s);
    }
  }
  return sheet;
}

}  // namespace grains::viewer
