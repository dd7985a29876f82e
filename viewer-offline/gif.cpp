#include "viewer-offline/gif.h"

#include <algorithm>
#include <stdexcept>

namespace grains::viewer {
namespace {

constexpr int kLevelsR = 6, kLevelsG = 7, kLevelsB = 6;  // 252 colours, then 4 greys
const int kBayer4[4][4] = {{0, 8, 2, 10}, {12, 4, 14, 6}, {3, 11, 1, 9}, {15, 7, 13, 5}};

uint8_t level_value(int q, int levels) {
  return static_cast<uint8_t>((q * 255 + (levels - 1) / 2) / (levels - 1));
}

// quantises one channel with an ordered-dither threshold in [0, 1)
int dither(uint8_t v, int levels, float threshold) {
  // a level's own byte stays on it: there `scaled` is within 0.012 above an integer (the green
  // levels are rounded) and the threshold is at most 31/32
  float scaled = v * static_cast<float>(levels - 1) / 255.0f;
  return std::clamp(static_cast<int>(scaled + threshold), 0, levels - 1);
}

// LZW coder for one frame's indices (GIF flavour: LSB-first codes, 8-bit roots).
class LzwEncoder {
 public:
  explicit LzwEncoder(std::vector<uint8_t>& out) : out_(out), table_(1 << 20, -1) {}

  void encode(const std::vector<uint8_t>& idx) {
    reset();
    put(kClear);
    if (idx.empty()) {
      put(kEnd);
      flush();
      return;
    }
    int cur = idx[0];
    for (size_t i = 1; i < idx.size(); ++i) {
      int key = (cur << 8) | idx[i];
      int16_t hit = table_[key];
      if (hit >= 0) {
        cur = hit;
        continue;
      }
      put(cur);
      table_[key] = static_cast<int16_t>(++max_code_);
      used_.push_back(key);
      if (max_code_ >= (1 << code_size_) && code_size_ < 12) ++code_size_;
      if (max_code_ == 4095) {  // table full: start over
        put(kClear);
        reset();
      }
      cur = idx[i];
    }
    put(cur);
    // the decoder adds one more entry after this last code, and may widen its codes: follow it
    ++max_code_;
    if (max_code_ >= (1 << code_size_) && code_size_ < 12) ++code_size_;
    put(kEnd);
    flush();
  }

 private:
  static constexpr int kClear = 256, kEnd = 257;
  void reset() {
    for (int k : used_) table_[k] = -1;
    used_.clear();
    code_size_ = 9;
    max_code_ = kEnd;
  }
  void put(int code) {
    bits_ |= static_cast<uint32_t>(code) << nbits_;
    nbits_ += code_size_;
    while (nbits_ >= 8) {
      out_.push_back(static_cast<uint8_t>(bits_ & 0xff));
      bits_ >>= 8;
      nbits_ -= 8;
    }
  }
  void flush() {
    if (nbits_ > 0) out_.push_back(static_cast<uint8_t>(bits_ & 0xff));
    bits_ = 0;
    nbits_ = 0;
  }

  std::vector<uint8_t>& out_;
  std::vector<int16_t> table_;  // (prefix code << 8 | byte) → code, -1 when absent
  std::vector<int> used_;       // keys set since the last clear
  int code_size_ = 9, max_code_ = kEnd;
  uint32_t bits_ = 0;
  int nbits_ = 0;
};

void put16(std::vector<uint8_t>& b, int v) {
  b.push_back(static_cast<uint8_t>(v & 0xff));
  b.push_back(static_cast<uint8_t>((v >> 8) & 0xff));
}

}  // namespace

const std::vector<uint8_t>& gif_palette() {
  static const std::vector<uint8_t> pal = [] {
    std::vector<uint8_t> p;
    for (int r = 0; r < kLevelsR; ++r)
      for (int g = 0; g < kLevelsG; ++g)
        for (int b = 0; b < kLevelsB; ++b) {
          p.push_back(level_value(r, kLevelsR));
          p.push_back(level_value(g, kLevelsG));
          p.push_back(level_value(b, kLevelsB));
        }
    for (int k = 1; k <= 4; ++k)  // greys between the cube's grey levels
      for (int c = 0; c < 3; ++c) p.push_back(static_cast<uint8_t>(k * 51 - 25));
    return p;
  }();
  return pal;
}

uint8_t gif_palette_index(uint8_t r, uint8_t g, uint8_t b, int x, int y) {
  float t = (kBayer4[y & 3][x & 3] + 0.5f) / 16.0f;
  int qr = dither(r, kLevelsR, t), qg = dither(g, kLevelsG, t), qb = dither(b, kLevelsB, t);
  return static_cast<uint8_t>((qr * kLevelsG + qg) * kLevelsB + qb);
}

GifWriter::GifWriter(const std::string& path, int width, int height, int delay_cs)
    : path_(path), width_(width), height_(height), delay_cs_(delay_cs) {
  if (width <= 0 || height <= 0 || width > 65535 || height > 65535)
    throw std::runtime_error(path + ": GIF size out of range");
  f_ = std::fopen(path.c_str(), "wb");
  if (!f_) throw std::runtime_error(path + ": cannot open for writing");
  std::vector<uint8_t> h = {'G', 'I', 'F', '8', '9', 'a'};
  put16(h, width);
  put16(h, height);
  h.push_back(0xF7);  // global colour table of 256 entries, 8 bits per primary
  h.push_back(0);     // background colour index
  h.push_back(0);     // square pixels
  const auto& pal = gif_palette();
  h.insert(h.end(), pal.begin(), pal.end());
  // NETSCAPE2.0 application extension: loop forever
  const uint8_t loop[] = {0x21, 0xFF, 0x0B, 'N', 'E',  'T',  'S',  'C',  'A', 'P',
                          'E',  '2',  '.',  '0', 0x03, 0x01, 0x00, 0x00, 0x00};
  h.insert(h.end(), loop, loop + sizeof loop);
  if (std::fwrite(h.data(), 1, h.size(), f_) != h.size()) {
    std::fclose(f_);
    f_ = nullptr;
    throw std::runtime_error(path + ": write failed");
  }
}

GifWriter::~GifWriter() {
  try {
    close();
  } catch (...) {
  }
}

void GifWriter::add_frame(const Image& img) {
  if (!f_) throw std::runtime_error(path_ + ": GIF already closed");
  if (img.width != width_ || img.height != height_)
    throw std::runtime_error(path_ + ": frame size differs from the first frame");
  std::vector<uint8_t> idx(static_cast<size_t>(width_) * height_);
  for (int y = 0; y < height_; ++y)
    for (int x = 0; x < width_; ++x) {
      const uint8_t* p = img.px(x, y);
      idx[static_cast<size_t>(y) * width_ + x] = gif_palette_index(p[0], p[1], p[2], x, y);
    }
  std::vector<uint8_t> b;
  // graphic control extension: no disposal, the delay, no transparency
  const uint8_t gce[] = {0x21, 0xF9, 0x04, 0x04};
  b.insert(b.end(), gce, gce + sizeof gce);
  put16(b, delay_cs_);
  b.push_back(0);
  b.push_back(0);
  // image descriptor: the whole canvas, no local colour table
  b.push_back(0x2C);
  put16(b, 0);
  put16(b, 0);
  put16(b, width_);
  put16(b, height_);
  b.push_back(0);
  b.push_back(8);  // LZW minimum code size
  std::vector<uint8_t> codes;
  LzwEncoder(codes).encode(idx);
  for (size_t k = 0; k < codes.size(); k += 255) {  // data sub-blocks of at most 255 bytes
    size_t len = std::min<size_t>(255, codes.size() - k);
    b.push_back(static_cast<uint8_t>(len));
    b.insert(b.end(), codes.begin() + k, codes.begin() + k + len);
  }
  b.push_back(0);
  if (std::fwrite(b.data(), 1, b.size(), f_) != b.size())
    throw std::runtime_error(path_ + ": write failed");
}

void GifWriter::close() {
  if (!f_) return;
  bool ok = std::fputc(0x3B, f_) != EOF;
  ok = (std::fclose(f_) == 0) && ok;
  f_ = nullptr;
  if (!ok) throw std::runtime_error(path_ + ": write failed");
}

}  // namespace grains::viewer
