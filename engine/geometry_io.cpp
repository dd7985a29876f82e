// PLY frames (DESIGN §6) and PLY/OBJ inputs. See geometry_io.h.
//
// Writing builds one byte buffer per element (columns copied in row blocks) and writes it with a
// single fwrite, to PATH.tmp, then renames. Reading loads the whole file, parses the header, and
// decodes each element either column by column (binary elements without list properties: fixed
// row stride) or row by row (ascii, or elements with lists), straight into the store's arrays.
#include "engine/geometry_io.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

namespace grains {

namespace {

constexpr bool kHostLittle = std::endian::native == std::endian::little;

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw GeometryError(path + ": " + what);
}

[[noreturn]] void write_fail(const std::string& path, const std::string& what, int err) {
  throw WriteError(path + ": " + what + " (" + std::strerror(err) + ")");
}

// "NaN" or "infinite": what a non-finite number read from a file is called in its error
const char* non_finite_name(float x) { return std::isnan(x) ? "NaN" : "infinite"; }

std::string read_whole_file(const std::string& path) {
  if (std::string bad = input_file_problem(path, kMaxGeometryFileBytes); !bad.empty())
    fail(path, bad);
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot open (") + std::strerror(errno) + ")");
  std::string data;
  in.seekg(0, std::ios::end);
  std::streamoff size = in.tellg();
  if (size < 0) fail(path, "cannot read");
  data.resize(static_cast<size_t>(size));
  in.seekg(0, std::ios::beg);
  if (size > 0 && !in.read(data.data(), size)) fail(path, "cannot read");
  return data;
}

std::vector<std::string> split_ws(std::string_view line) {
  std::vector<std::string> out;
  size_t k = 0;
  while (k < line.size()) {
    while (k < line.size() && std::isspace(static_cast<unsigned char>(line[k]))) ++k;
    size_t b = k;
    while (k < line.size() && !std::isspace(static_cast<unsigned char>(line[k]))) ++k;
    if (k > b) out.emplace_back(line.substr(b, k - b));
  }
  return out;
}

// ------------------------------------------------------------------------------------------------
// Writing

bool valid_property_name(const std::string& name) {
  if (name.empty()) return false;
  for (unsigned char c : name)
    if (c <= ' ' || c >= 127) return false;
  return true;
}

// One 4-byte column of an element: src[r * stride] (in 4-byte units), or a constant when src is
// null.
struct Column {
  const unsigned char* src = nullptr;
  size_t stride = 0;  // in 4-byte units
  unsigned char constant[4] = {0, 0, 0, 0};
};

struct ElementOut {
  std::string name;
  size_t count = 0;
  std::vector<std::string> header;  // "property float x" lines
  std::vector<Column> cols;
  std::set<std::string> names;

  void add(const std::string& path, const char* type, const std::string& prop, Column c) {
    if (!valid_property_name(prop)) fail(path, "cannot write property '" + prop + "' (bad name)");
    if (!names.insert(prop).second)
      fail(path, "cannot write " + name + " property '" + prop + "' twice");
    header.push_back(std::string("property ") + type + " " + prop);
    cols.push_back(c);
  }
  void add_float(const std::string& path, const std::string& prop, const float* base,
                 size_t stride) {
    Column c;
    c.src = reinterpret_cast<const unsigned char*>(base);
    c.stride = stride;
    add(path, "float", prop, c);
  }
  void add_float_const(const std::string& path, const std::string& prop, float value) {
    Column c;
    std::memcpy(c.constant, &value, 4);
    add(path, "float", prop, c);
  }
  void add_int(const std::string& path, const std::string& prop, const int32_t* base,
               size_t stride) {
    Column c;
    c.src = reinterpret_cast<const unsigned char*>(base);
    c.stride = stride;
    add(path, "int", prop, c);
  }
  void add_int_const(const std::string& path, const std::string& prop, int32_t value) {
    Column c;
    std::memcpy(c.constant, &value, 4);
    add(path, "int", prop, c);
  }

  // Fills the binary little-endian rows.
  std::unique_ptr<unsigned char[]> encode(size_t& bytes) const {
    const size_t row = cols.size() * 4;
    bytes = row * count;
    std::unique_ptr<unsigned char[]> buf(new unsigned char[bytes > 0 ? bytes : 1]);
    unsigned char* out = buf.get();
    constexpr size_t kBlock = 2048;
    for (size_t r0 = 0; r0 < count; r0 += kBlock) {
      const size_t r1 = std::min(count, r0 + kBlock);
      for (size_t c = 0; c < cols.size(); ++c) {
        const Column& col = cols[c];
        unsigned char* dst = out + c * 4;
        if (col.src) {
          const size_t step = col.stride * 4;
          for (size_t r = r0; r < r1; ++r) std::memcpy(dst + r * row, col.src + r * step, 4);
        } else {
          for (size_t r = r0; r < r1; ++r) std::memcpy(dst + r * row, col.constant, 4);
        }
      }
    }
    if constexpr (!kHostLittle)
      for (size_t k = 0; k < bytes; k += 4) {
        std::swap(out[k], out[k + 3]);
        std::swap(out[k + 1], out[k + 2]);
      }
    return buf;
  }
};

// Component k of an interleaved array as a column start; an empty array's null data() takes no
// offset (null plus k is undefined), and a column of no rows is never read.
template <class T>
const T* column(const std::vector<T>& v, size_t k) {
  return v.empty() ? nullptr : v.data() + k;
}

// Adds one point attribute (by name) to the vertex element: from the store, or else with its
// documented default.
void add_point_attribute(const std::string& path, ElementOut& el, const ParticleStore& pts,
                         const std::string& name) {
  if (const Attribute* a = pts.find(name)) {
    switch (a->type) {
      case AttribType::Float: el.add_float(path, name, a->f.data(), 1); return;
      case AttribType::Int: el.add_int(path, name, a->i.data(), 1); return;
      case AttribType::Vec3:
        el.add_float(path, name + "_x", column(a->f, 0), 3);
        el.add_float(path, name + "_y", column(a->f, 1), 3);
        el.add_float(path, name + "_z", column(a->f, 2), 3);
        return;
    }
  }
  const AttribDefault* d = find_known_attribute(name);
  if (!d) fail(path, "cannot write attribute '" + name + "': not in the store and not a known attribute");
  switch (d->type) {
    case AttribType::Float: el.add_float_const(path, name, d->value[0]); return;
    case AttribType::Int: el.add_int_const(path, name, static_cast<int32_t>(d->value[0])); return;
    case AttribType::Vec3:
      el.add_float_const(path, name + "_x", d->value[0]);
      el.add_float_const(path, name + "_y", d->value[1]);
      el.add_float_const(path, name + "_z", d->value[2]);
      return;
  }
}

// The fixed vertex columns: x y z, vx vy vz, pscale, id (from the store, or their defaults).
void add_fixed_vertex_columns(const std::string& path, ElementOut& el, const ParticleStore& pts) {
  static const char* const comps[2][3] = {{"x", "y", "z"}, {"vx", "vy", "vz"}};
  int which = 0;
  for (const char* name : {"P", "v"}) {
    const Attribute* a = pts.find(name);
    if (a && a->type != AttribType::Vec3)
      fail(path, std::string("cannot write: ") + name + " is not a vector attribute");
    for (int c = 0; c < 3; ++c) {
      if (a)
        el.add_float(path, comps[which][c], column(a->f, c), 3);
      else
        el.add_float_const(path, comps[which][c], 0.0f);
    }
    ++which;
  }
  const Attribute* ps = pts.find("pscale");
  if (ps && ps->type != AttribType::Float) fail(path, "cannot write: pscale is not a float attribute");
  if (ps)
    el.add_float(path, "pscale", ps->f.data(), 1);
  else
    el.add_float_const(path, "pscale", find_known_attribute("pscale")->value[0]);
  const Attribute* id = pts.find("id");
  if (!id || id->type != AttribType::Int) fail(path, "cannot write: the store has no int id attribute");
  el.add_int(path, "id", id->i.data(), 1);
}

bool is_fixed_point_attribute(const std::string& name) {
  return name == "P" || name == "v" || name == "pscale" || name == "id";
}

ElementOut edge_element(const std::string& path, const ParticleStore& pts, bool all) {
  ElementOut el;
  el.name = "edge";
  el.count = pts.prim_count();
  el.add_int(path, "vertex1", column(pts.prim_points(), 0), 2);
  el.add_int(path, "vertex2", column(pts.prim_points(), 1), 2);
  for (const char* name : {"restlength", "strain"}) {
    if (const float* p = pts.prim_f_if(name))
      el.add_float(path, name, p, 1);
    else
      el.add_float_const(path, name, 0.0f);
  }
  if (all)
    for (const auto& [name, values] : pts.prim_attributes()) {
      if (name == "restlength" || name == "strain") continue;
      el.add_float(path, name, values.data(), 1);
    }
  return el;
}

void write_elements(const std::string& path, const std::vector<ElementOut>& elements) {
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  for (const ElementOut& el : elements) {
    header += "element " + el.name + " " + std::to_string(el.count) + "\n";
    for (const std::string& line : el.header) header += line + "\n";
  }
  header += "end_header\n";

  write_file_atomically(path, [&](std::FILE* f) {
    bool ok = std::fwrite(header.data(), 1, header.size(), f) == header.size();
    for (const ElementOut& el : elements) {
      if (!ok) break;
      size_t bytes = 0;
      std::unique_ptr<unsigned char[]> buf = el.encode(bytes);
      ok = std::fwrite(buf.get(), 1, bytes, f) == bytes;
    }
    return ok;
  });
}

// ------------------------------------------------------------------------------------------------
// Reading

enum class PlyType { Char, UChar, Short, UShort, Int, UInt, Float, Double };

std::optional<PlyType> parse_ply_type(const std::string& s) {
  static const std::map<std::string, PlyType, std::less<>> types = {
      {"char", PlyType::Char},     {"int8", PlyType::Char},     {"uchar", PlyType::UChar},
      {"uint8", PlyType::UChar},   {"short", PlyType::Short},   {"int16", PlyType::Short},
      {"ushort", PlyType::UShort}, {"uint16", PlyType::UShort}, {"int", PlyType::Int},
      {"int32", PlyType::Int},     {"uint", PlyType::UInt},     {"uint32", PlyType::UInt},
      {"float", PlyType::Float},   {"float32", PlyType::Float}, {"double", PlyType::Double},
      {"float64", PlyType::Double},
  };
  auto it = types.find(s);
  if (it == types.end()) return std::nullopt;
  return it->second;
}

size_t type_size(PlyType t) {
  switch (t) {
    case PlyType::Char:
    case PlyType::UChar: return 1;
    case PlyType::Short:
    case PlyType::UShort: return 2;
    case PlyType::Int:
    case PlyType::UInt:
    case PlyType::Float: return 4;
    case PlyType::Double: return 8;
  }
  return 1;
}

bool is_integer_type(PlyType t) { return t != PlyType::Float && t != PlyType::Double; }

struct PlyProp {
  std::string name;
  std::string type_name;  // as written
  PlyType type = PlyType::Float;
  bool is_list = false;
  PlyType count_type = PlyType::UChar;
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProp> props;
  const PlyProp* find(std::string_view n) const {
    for (const PlyProp& p : props)
      if (p.name == n) return &p;
    return nullptr;
  }
  int index(std::string_view n) const {
    for (size_t k = 0; k < props.size(); ++k)
      if (props[k].name == n) return static_cast<int>(k);
    return -1;
  }
};

enum class PlyFormat { Ascii, BinaryLittle, BinaryBig };

// Where one property's values go.
struct Sink {
  enum Kind { Skip, Float, Int, List } kind = Skip;
  float* f = nullptr;
  int32_t* i = nullptr;
  size_t stride = 1;
  std::vector<int32_t>* items = nullptr;    // List: all items, concatenated
  std::vector<uint32_t>* counts = nullptr;  // List: one count per row
};

int32_t to_int32(double d) {
  if (!(d >= -2147483648.0 && d <= 4294967295.0)) return std::numeric_limits<int32_t>::min();
  return static_cast<int32_t>(static_cast<int64_t>(d));
}

template <class T>
T load(const unsigned char* p, bool swap) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

template <class T>
int32_t to_int32_typed(T v) {
  if constexpr (std::is_floating_point_v<T>)
    return to_int32(static_cast<double>(v));
  else
    return static_cast<int32_t>(v);
}

template <class T>
void decode_column(const unsigned char* base, size_t count, size_t row, bool swap, const Sink& s) {
  if (s.kind == Sink::Float) {
    for (size_t r = 0; r < count; ++r)
      s.f[r * s.stride] = static_cast<float>(load<T>(base + r * row, swap));
  } else if (s.kind == Sink::Int) {
    for (size_t r = 0; r < count; ++r)
      s.i[r * s.stride] = to_int32_typed(load<T>(base + r * row, swap));
  }
}

class PlyReader {
 public:
  explicit PlyReader(const std::string& path) : path_(path), data_(read_whole_file(path)) {
    parse_header();
  }
  const std::string& path() const { return path_; }
  const std::vector<PlyElement>& elements() const { return elements_; }

  // Throws if the data left cannot hold element e, the next one to read (call before allocating
  // anything for its count).
  void check_remaining(size_t e) const {
    const PlyElement& el = elements_[e];
    size_t min_row = 0;  // bytes (binary) or values (ascii, each at least one char and a space)
    for (const PlyProp& p : el.props)
      min_row += format_ == PlyFormat::Ascii ? 1 : type_size(p.is_list ? p.count_type : p.type);
    const size_t remaining = data_.size() - pos_;
    if (min_row > 0 && el.count > remaining / min_row) truncated(el);
  }

  // Reads the next element's data (elements must be read in order) into one sink per property.
  void read_element(size_t e, const std::vector<Sink>& sinks) {
    if (e != next_element_) throw std::logic_error("PlyReader: elements read out of order");
    ++next_element_;
    const PlyElement& el = elements_[e];
    check_remaining(e);
    if (el.props.empty()) return;
    bool has_list = false;
    size_t row = 0;
    for (const PlyProp& p : el.props) {
      has_list |= p.is_list;
      row += p.is_list ? type_size(p.count_type) : type_size(p.type);
    }

    if (format_ != PlyFormat::Ascii && !has_list) {
      const unsigned char* base = reinterpret_cast<const unsigned char*>(data_.data()) + pos_;
      size_t off = 0;
      for (size_t k = 0; k < el.props.size(); ++k) {
        const PlyProp& p = el.props[k];
        const Sink& s = sinks[k];
        if (s.kind == Sink::Float || s.kind == Sink::Int) {
          const unsigned char* b = base + off;
          switch (p.type) {
            case PlyType::Char: decode_column<int8_t>(b, el.count, row, swap_, s); break;
            case PlyType::UChar: decode_column<uint8_t>(b, el.count, row, swap_, s); break;
            case PlyType::Short: decode_column<int16_t>(b, el.count, row, swap_, s); break;
            case PlyType::UShort: decode_column<uint16_t>(b, el.count, row, swap_, s); break;
            case PlyType::Int: decode_column<int32_t>(b, el.count, row, swap_, s); break;
            case PlyType::UInt: decode_column<uint32_t>(b, el.count, row, swap_, s); break;
            case PlyType::Float: decode_column<float>(b, el.count, row, swap_, s); break;
            case PlyType::Double: decode_column<double>(b, el.count, row, swap_, s); break;
          }
        }
        off += type_size(p.type);
      }
      pos_ += row * el.count;
      return;
    }

    for (size_t r = 0; r < el.count; ++r) {
      for (size_t k = 0; k < el.props.size(); ++k) {
        const PlyProp& p = el.props[k];
        const Sink& s = sinks[k];
        if (p.is_list) {
          double c = value(p.count_type, el);
          if (!(c >= 0 && c <= 1e9) || c != std::floor(c))
            fail(path_, "bad list length in element '" + el.name + "'");
          const size_t n = static_cast<size_t>(c);
          if (s.kind == Sink::List) {
            s.counts->push_back(static_cast<uint32_t>(n));
            for (size_t j = 0; j < n; ++j) s.items->push_back(to_int32(value(p.type, el)));
          } else if (format_ != PlyFormat::Ascii) {
            const size_t bytes = n * type_size(p.type);
            if (bytes > data_.size() - pos_) truncated(el);
            pos_ += bytes;
          } else {
            for (size_t j = 0; j < n; ++j) value(p.type, el);
          }
        } else {
          double d = value(p.type, el);
          if (s.kind == Sink::Float)
            s.f[r * s.stride] = static_cast<float>(d);
          else if (s.kind == Sink::Int)
            s.i[r * s.stride] = to_int32(d);
          else if (s.kind == Sink::List) {
            s.counts->push_back(1);
            s.items->push_back(to_int32(d));
          }
        }
      }
    }
  }

 private:
  [[noreturn]] void truncated(const PlyElement& el) const {
    fail(path_, "truncated data in element '" + el.name + "'");
  }

  double value(PlyType t, const PlyElement& el) {
    if (format_ == PlyFormat::Ascii) {
      const char* d = data_.data();
      const size_t n = data_.size();
      while (pos_ < n && std::isspace(static_cast<unsigned char>(d[pos_]))) ++pos_;
      if (pos_ >= n) truncated(el);
      size_t b = pos_;
      while (pos_ < n && !std::isspace(static_cast<unsigned char>(d[pos_]))) ++pos_;
      const char* first = d + b;
      if (*first == '+') ++first;
      double v = 0;
      auto [ptr, ec] = std::from_chars(first, d + pos_, v);
      if (ec != std::errc() || ptr != d + pos_)
        fail(path_, "bad number '" + std::string(d + b, pos_ - b) + "' in element '" + el.name +
                        "'");
      return v;
    }
    const size_t sz = type_size(t);
    if (sz > data_.size() - pos_) truncated(el);
    const unsigned char* p = reinterpret_cast<const unsigned char*>(data_.data()) + pos_;
    pos_ += sz;
    switch (t) {
      case PlyType::Char: return load<int8_t>(p, swap_);
      case PlyType::UChar: return load<uint8_t>(p, swap_);
      case PlyType::Short: return load<int16_t>(p, swap_);
      case PlyType::UShort: return load<uint16_t>(p, swap_);
      case PlyType::Int: return load<int32_t>(p, swap_);
      case PlyType::UInt: return load<uint32_t>(p, swap_);
      case PlyType::Float: return load<float>(p, swap_);
      case PlyType::Double: return load<double>(p, swap_);
    }
    return 0;
  }

  void parse_header() {
    size_t pos = 0, line_no = 0;
    bool have_format = false, have_end = false;
    auto next_line = [&](std::string& line) {
      if (pos >= data_.size()) return false;
      size_t e = data_.find('\n', pos);
      if (e == std::string::npos) e = data_.size();
      line.assign(data_, pos, e - pos);
      if (!line.empty() && line.back() == '\r') line.pop_back();
      pos = std::min(data_.size(), e + 1);
      ++line_no;
      return true;
    };
    std::string line;
    if (!next_line(line) || line != "ply") fail(path_, "not a PLY file (no 'ply' magic line)");
    while (next_line(line)) {
      auto bad = [&](const std::string& why) {
        fail(path_, "header line " + std::to_string(line_no) + ": " + why + ": '" + line + "'");
      };
      std::vector<std::string> tok = split_ws(line);
      if (tok.empty()) continue;
      const std::string& kw = tok[0];
      if (kw == "comment" || kw == "obj_info") continue;
      if (kw == "end_header") {
        have_end = true;
        break;
      }
      if (kw == "format") {
        if (tok.size() < 2) bad("bad format line");
        if (tok[1] == "ascii")
          format_ = PlyFormat::Ascii;
        else if (tok[1] == "binary_little_endian")
          format_ = PlyFormat::BinaryLittle;
        else if (tok[1] == "binary_big_endian")
          format_ = PlyFormat::BinaryBig;
        else
          bad("unknown format '" + tok[1] + "'");
        have_format = true;
      } else if (kw == "element") {
        if (tok.size() != 3) bad("bad element line");
        PlyElement el;
        el.name = tok[1];
        unsigned long long c = 0;
        auto [ptr, ec] = std::from_chars(tok[2].data(), tok[2].data() + tok[2].size(), c);
        if (ec != std::errc() || ptr != tok[2].data() + tok[2].size()) bad("bad element count");
        el.count = static_cast<size_t>(c);
        elements_.push_back(std::move(el));
      } else if (kw == "property") {
        if (elements_.empty()) bad("property before any element");
        PlyProp p;
        if (tok.size() >= 2 && tok[1] == "list") {
          if (tok.size() != 5) bad("bad list property line");
          auto ct = parse_ply_type(tok[2]);
          auto it = parse_ply_type(tok[3]);
          if (!ct || !it) bad("unknown property type");
          if (!is_integer_type(*ct)) bad("list length type must be an integer type");
          p.is_list = true;
          p.count_type = *ct;
          p.type = *it;
          p.type_name = tok[3];
          p.name = tok[4];
        } else {
          if (tok.size() != 3) bad("bad property line");
          auto t = parse_ply_type(tok[1]);
          if (!t) bad("unknown property type '" + tok[1] + "'");
          p.type = *t;
          p.type_name = tok[1];
          p.name = tok[2];
        }
        PlyElement& el = elements_.back();
        // a name the writer could not write back (valid_property_name) is refused here
        if (!valid_property_name(p.name)) bad("a property name is printable ASCII");
        if (el.find(p.name)) bad("duplicate property '" + p.name + "'");
        el.props.push_back(std::move(p));
      } else {
        bad("unknown header keyword");
      }
    }
    if (!have_end) fail(path_, "header has no end_header");
    if (!have_format) fail(path_, "header has no format line");
    pos_ = pos;
    const bool file_little = format_ == PlyFormat::BinaryLittle;
    swap_ = format_ != PlyFormat::Ascii && file_little != kHostLittle;
  }

  std::string path_;
  std::string data_;
  std::vector<PlyElement> elements_;
  PlyFormat format_ = PlyFormat::Ascii;
  bool swap_ = false;
  size_t pos_ = 0;  // data position
  size_t next_element_ = 0;
};

std::vector<Sink> skip_sinks(const PlyElement& el) { return std::vector<Sink>(el.props.size()); }

// "a float attribute", "an int attribute", "a vector attribute".
std::string a_type(AttribType t) {
  return std::string(t == AttribType::Int ? "an " : "a ") + attrib_type_name(t) + " attribute";
}

// Vertex property → point attribute component.
struct Dest {
  std::string attr;
  AttribType type = AttribType::Float;
  int comp = 0;
};

std::vector<std::optional<Dest>> map_vertex_properties(const std::string& path,
                                                       const PlyElement& el) {
  std::vector<std::optional<Dest>> dest(el.props.size());
  auto scalar = [&](std::string_view n) -> int {
    int k = el.index(n);
    return k >= 0 && !el.props[k].is_list ? k : -1;
  };
  std::set<std::string> vectors;  // Vec3 attributes mapped so far
  auto map_vec = [&](const std::string& attr, int kx, int ky, int kz, const std::string& what) {
    if (!vectors.insert(attr).second)
      fail(path, "vertex properties " + what + " give " + attr + " a second time");
    const AttribDefault* d = find_known_attribute(attr);
    if (d && d->type != AttribType::Vec3)
      fail(path, "vertex properties " + what + " form a vector, but " + attr + " is " + a_type(d->type));
    dest[kx] = Dest{attr, AttribType::Vec3, 0};
    dest[ky] = Dest{attr, AttribType::Vec3, 1};
    dest[kz] = Dest{attr, AttribType::Vec3, 2};
  };
  {
    int kx = scalar("x"), ky = scalar("y"), kz = scalar("z");
    if (kx >= 0 && ky >= 0 && kz >= 0) map_vec("P", kx, ky, kz, "'x y z'");
    int vx = scalar("vx"), vy = scalar("vy"), vz = scalar("vz");
    if (vx >= 0 && vy >= 0 && vz >= 0) map_vec("v", vx, vy, vz, "'vx vy vz'");
  }
  for (size_t k = 0; k < el.props.size(); ++k) {
    const std::string& n = el.props[k].name;
    if (dest[k] || el.props[k].is_list || n.size() < 3 || n.compare(n.size() - 2, 2, "_x") != 0)
      continue;
    const std::string base = n.substr(0, n.size() - 2);
    int ky = scalar(base + "_y"), kz = scalar(base + "_z");
    if (ky < 0 || kz < 0 || dest[ky] || dest[kz]) continue;
    map_vec(base, static_cast<int>(k), ky, kz, "'" + n + " " + base + "_y " + base + "_z'");
  }
  if (!vectors.count("P")) fail(path, "vertex element has no x/y/z properties");
  for (size_t k = 0; k < el.props.size(); ++k) {
    const PlyProp& p = el.props[k];
    if (dest[k] || p.is_list) continue;
    const AttribType t = is_integer_type(p.type) ? AttribType::Int : AttribType::Float;
    const AttribDefault* d = find_known_attribute(p.name);
    if (d && d->type != t)
      fail(path, "vertex property '" + p.name + "' is " + p.type_name + ", but " + p.name + " is " +
                     a_type(d->type));
    if (vectors.count(p.name))
      fail(path, "vertex property '" + p.name + "' clashes with the vector " + p.name);
    // x y z and vx vy vz are the written columns of P and v: never attributes of their own
    for (const char* set : {"x y z", "vx vy vz"})
      for (const std::string& c : split_ws(set))
        if (p.name == c)
          fail(path, "vertex property '" + p.name + "' comes without the rest of '" + set + "'");
    dest[k] = Dest{p.name, t, 0};
  }
  return dest;
}

struct EdgeData {
  std::vector<int32_t> v1, v2;
  std::map<std::string, std::vector<float>> attrs;
};

std::vector<Sink> edge_sinks(const std::string& path, const PlyElement& el, EdgeData& e) {
  std::vector<Sink> sinks(el.props.size());
  int k1 = el.index("vertex1"), k2 = el.index("vertex2");
  if (k1 < 0 || k2 < 0 || el.props[k1].is_list || el.props[k2].is_list)
    fail(path, "edge element needs vertex1 and vertex2 properties");
  e.v1.assign(el.count, 0);
  e.v2.assign(el.count, 0);
  sinks[k1].kind = Sink::Int;
  sinks[k1].i = e.v1.data();
  sinks[k2].kind = Sink::Int;
  sinks[k2].i = e.v2.data();
  for (size_t k = 0; k < el.props.size(); ++k) {
    const PlyProp& p = el.props[k];
    if (static_cast<int>(k) == k1 || static_cast<int>(k) == k2 || p.is_list) continue;
    std::vector<float>& v = e.attrs[p.name];
    v.assign(el.count, 0.0f);
    sinks[k].kind = Sink::Float;
    sinks[k].f = v.data();
  }
  return sinks;
}

std::string lower_extension(const std::string& path) {
  size_t slash = path.find_last_of("/\\");
  size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

// Fan-triangulates polygons given as concatenated vertex lists, validating indices.
void add_polygons(const std::string& where, Mesh& mesh, const std::vector<int32_t>& items,
                  const std::vector<uint32_t>& counts) {
  const int32_t n = static_cast<int32_t>(mesh.vertices.size());
  size_t at = 0;
  for (size_t f = 0; f < counts.size(); ++f) {
    const size_t c = counts[f];
    for (size_t j = 0; j < c; ++j)
      if (items[at + j] < 0 || items[at + j] >= n)
        fail(where, "face " + std::to_string(f) + " has vertex index " +
                        std::to_string(items[at + j]) + " out of range (" + std::to_string(n) +
                        " vertices)");
    for (size_t j = 1; j + 1 < c; ++j)
      mesh.triangles.push_back({items[at], items[at + j], items[at + j + 1]});
    at += c;
  }
}

Mesh read_ply_mesh(const std::string& path) {
  PlyReader r(path);
  Mesh mesh;
  std::vector<int32_t> items;
  std::vector<uint32_t> counts;
  bool have_vertex = false;
  for (size_t e = 0; e < r.elements().size(); ++e) {
    const PlyElement& el = r.elements()[e];
    std::vector<Sink> sinks = skip_sinks(el);
    const bool vertex = el.name == "vertex" && !have_vertex;
    std::vector<float> xyz;
    if (vertex) {
      have_vertex = true;
      int k[3] = {el.index("x"), el.index("y"), el.index("z")};
      for (int c = 0; c < 3; ++c)
        if (k[c] < 0 || el.props[k[c]].is_list) fail(path, "vertex element has no x/y/z properties");
      r.check_remaining(e);
      xyz.assign(el.count * 3, 0.0f);
      // no vertices: nothing to point into (a null data() plus a component is undefined)
      for (int c = 0; c < 3 && el.count > 0; ++c) {
        sinks[k[c]].kind = Sink::Float;
        sinks[k[c]].f = xyz.data() + c;
        sinks[k[c]].stride = 3;
      }
    } else if (el.name == "face") {
      int k = el.index("vertex_indices");
      if (k < 0) k = el.index("vertex_index");
      if (k >= 0 && el.props[k].is_list) {
        sinks[k].kind = Sink::List;
        sinks[k].items = &items;
        sinks[k].counts = &counts;
      }
    }
    r.read_element(e, sinks);
    if (vertex) {
      mesh.vertices.resize(el.count);
      for (size_t p = 0; p < el.count; ++p) mesh.vertices[p] = load3(xyz.data(), p);
      for (size_t q = 0; q < xyz.size(); ++q)
        if (!std::isfinite(xyz[q]))
          fail(path, "vertex " + std::to_string(q / 3) + ": property '" + "xyz"[q % 3] + "' is " +
                         non_finite_name(xyz[q]));
    }
  }
  if (!have_vertex) fail(path, "no vertex element");
  add_polygons(path, mesh, items, counts);
  return mesh;
}

}  // namespace

// ------------------------------------------------------------------------------------------------

void write_file_atomically(const std::string& path, const std::function<bool(std::FILE*)>& write) {
  const std::string tmp = path + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) write_fail(path, "cannot write", errno);
  bool ok = write(f);
  int err = ok ? 0 : errno;
  if (std::fclose(f) != 0 && ok) {
    ok = false;
    err = errno;
  }
  if (!ok) {
    std::remove(tmp.c_str());
    write_fail(path, "cannot write", err);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    err = errno;
    std::remove(tmp.c_str());
    write_fail(path, "cannot rename " + tmp, err);
  }
}

void write_ply(const std::string& path, const ParticleStore& pts,
               const std::vector<std::string>& attributes) {
  ElementOut vertex;
  vertex.name = "vertex";
  vertex.count = pts.size();
  add_fixed_vertex_columns(path, vertex, pts);
  std::set<std::string> seen;
  for (const std::string& name : attributes) {
    if (is_fixed_point_attribute(name) || !seen.insert(name).second) continue;
    add_point_attribute(path, vertex, pts, name);
  }
  write_elements(path, {vertex, edge_element(path, pts, false)});
}

void write_ply_all(const std::string& path, const ParticleStore& pts) {
  ElementOut vertex;
  vertex.name = "vertex";
  vertex.count = pts.size();
  add_fixed_vertex_columns(path, vertex, pts);
  for (const auto& [name, a] : pts.attributes())
    if (!is_fixed_point_attribute(name)) add_point_attribute(path, vertex, pts, name);
  write_elements(path, {vertex, edge_element(path, pts, true)});
}

ParticleStore read_ply(const std::string& path, std::vector<std::string>* from_file) {
  PlyReader r(path);
  const auto& elements = r.elements();
  int vi = -1, ei = -1;
  for (size_t e = 0; e < elements.size(); ++e) {
    if (elements[e].name == "vertex") {
      if (vi >= 0) fail(path, "more than one vertex element");
      vi = static_cast<int>(e);
    } else if (elements[e].name == "edge") {
      if (ei >= 0) fail(path, "more than one edge element");
      ei = static_cast<int>(e);
    }
  }
  if (vi < 0) fail(path, "no vertex element");
  const PlyElement& vel = elements[vi];
  const std::vector<std::optional<Dest>> dest = map_vertex_properties(path, vel);
  if (from_file) {
    from_file->clear();
    for (const auto& d : dest)
      if (d && std::find(from_file->begin(), from_file->end(), d->attr) == from_file->end())
        from_file->push_back(d->attr);
  }
  if (vel.count > static_cast<size_t>(std::numeric_limits<int32_t>::max()))
    fail(path, "too many vertices (" + std::to_string(vel.count) + ")");
  EdgeData edges;

  ParticleStore s;
  const int id_prop = vel.index("id");
  for (size_t e = 0; e < elements.size(); ++e) {
    if (static_cast<int>(e) == vi) {
      r.check_remaining(e);
      s.add_points(vel.count);
      for (const auto& d : dest)
        if (d) s.add(d->attr, d->type);
      std::vector<Sink> sinks(vel.props.size());
      for (size_t k = 0; k < dest.size(); ++k) {
        // no vertices: no arrays to point into (a null data() plus a component is undefined)
        if (!dest[k] || vel.count == 0) continue;
        Attribute* a = s.find(dest[k]->attr);
        Sink& sk = sinks[k];
        if (dest[k]->type == AttribType::Int) {
          sk.kind = Sink::Int;
          sk.i = a->i.data();
        } else {
          sk.kind = Sink::Float;
          sk.f = a->f.data() + dest[k]->comp;
          sk.stride = a->components();
        }
      }
      r.read_element(e, sinks);
    } else if (static_cast<int>(e) == ei) {
      // the edge count is checked against the bytes left before its arrays are allocated
      r.check_remaining(e);
      r.read_element(e, edge_sinks(path, elements[ei], edges));
    } else {
      r.read_element(e, skip_sinks(elements[e]));
    }
  }

  const size_t n = s.size();
  // a number that is not finite would spread through the solve to every grain it touches:
  // refused here, where its file, element and index are known (a double beyond the float range
  // arrives as infinity)
  for (size_t k = 0; k < dest.size(); ++k) {
    if (!dest[k] || dest[k]->type == AttribType::Int) continue;
    const Attribute* a = s.find(dest[k]->attr);
    const size_t stride = a->components();
    for (size_t i = 0; i < n; ++i) {
      const float x = a->f[i * stride + dest[k]->comp];
      if (!std::isfinite(x))
        fail(path, "vertex " + std::to_string(i) + ": property '" + vel.props[k].name + "' is " +
                       non_finite_name(x));
    }
  }
  for (const auto& [name, values] : edges.attrs)
    for (size_t p = 0; p < values.size(); ++p)
      if (!std::isfinite(values[p]))
        fail(path, "edge " + std::to_string(p) + ": property '" + name + "' is " +
                       non_finite_name(values[p]));
  if (id_prop >= 0 && !vel.props[id_prop].is_list && n > 0) {
    std::vector<int32_t> ids(s.i_if("id"), s.i_if("id") + n);
    std::sort(ids.begin(), ids.end());
    auto dup = std::adjacent_find(ids.begin(), ids.end());
    if (dup != ids.end()) fail(path, "duplicate point id " + std::to_string(*dup));
    if (ids.back() == std::numeric_limits<int32_t>::max())
      fail(path, "point id " + std::to_string(ids.back()) + " leaves no room for new ids");
    s.set_next_id(std::max(ids.back() + 1, 0));
  }

  if (ei >= 0) {
    const size_t m = edges.v1.size();
    for (size_t p = 0; p < m; ++p)
      for (int j = 0; j < 2; ++j) {
        int32_t v = j == 0 ? edges.v1[p] : edges.v2[p];
        if (v < 0 || static_cast<size_t>(v) >= n)
          fail(path, "edge " + std::to_string(p) + ": vertex" + std::to_string(j + 1) + " " +
                         std::to_string(v) + " is out of range (" + std::to_string(n) +
                         " points)");
      }
    std::vector<int32_t>& pp = s.prim_points();
    pp.resize(2 * m);
    for (size_t p = 0; p < m; ++p) {
      pp[2 * p] = edges.v1[p];
      pp[2 * p + 1] = edges.v2[p];
    }
    for (auto& [name, values] : edges.attrs) std::copy(values.begin(), values.end(), s.prim_f(name));
    if (!edges.attrs.count("restlength")) {
      float* rest = s.prim_f("restlength");
      const float* P = s.v3_if("P");
      for (size_t p = 0; p < m; ++p)
        rest[p] = length(load3(P, pp[2 * p]) - load3(P, pp[2 * p + 1]));
    }
  }
  return s;
}

Mesh read_obj(const std::string& path) {
  if (std::string bad = input_file_problem(path, kMaxGeometryFileBytes); !bad.empty())
    fail(path, bad);
  std::ifstream in(path);
  if (!in) fail(path, std::string("cannot open (") + std::strerror(errno) + ")");
  Mesh mesh;
  std::string line;
  size_t line_no = 0;
  int32_t max_index = 0;  // largest positive index, checked at the end (forward references)
  size_t max_line = 0;
  std::vector<int32_t> poly;
  auto where = [&](size_t l) { return path + ":" + std::to_string(l); };
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::vector<std::string> tok = split_ws(line);
    if (tok.empty()) continue;
    if (tok[0] == "v") {
      if (tok.size() < 4) fail(where(line_no), "vertex needs x y z");
      Vec3 p;
      for (int c = 0; c < 3; ++c) {
        const std::string& t = tok[1 + c];
        const char* first = t.data() + (t[0] == '+' ? 1 : 0);
        auto [ptr, ec] = std::from_chars(first, t.data() + t.size(), p[c]);
        if (ec != std::errc() || ptr != t.data() + t.size())
          fail(where(line_no), "bad number '" + t + "'");
        if (!std::isfinite(p[c]))
          fail(where(line_no), "vertex coordinate '" + t + "' is " + non_finite_name(p[c]));
      }
      mesh.vertices.push_back(p);
    } else if (tok[0] == "f") {
      if (tok.size() < 4) fail(where(line_no), "face needs at least 3 vertices");
      poly.clear();
      for (size_t k = 1; k < tok.size(); ++k) {
        const std::string& t = tok[k];
        size_t slash = t.find('/');
        const char* end = t.data() + (slash == std::string::npos ? t.size() : slash);
        long long idx = 0;
        auto [ptr, ec] = std::from_chars(t.data(), end, idx);
        if (ec != std::errc() || ptr != end || idx == 0)
          fail(where(line_no), "bad face vertex '" + t + "'");
        const long long nv = static_cast<long long>(mesh.vertices.size());
        long long v = idx > 0 ? idx - 1 : nv + idx;
        if (v < 0 || v > std::numeric_limits<int32_t>::max())
          fail(where(line_no), "face vertex '" + t + "' is out of range (" + std::to_string(nv) +
                                   " vertices so far)");
        if (idx > 0 && v >= max_index) {
          max_index = static_cast<int32_t>(v);
          max_line = line_no;
        }
        poly.push_back(static_cast<int32_t>(v));
      }
      for (size_t j = 1; j + 1 < poly.size(); ++j)
        mesh.triangles.push_back({poly[0], poly[j], poly[j + 1]});
    }
    // vt, vn, o, g, s, l, usemtl, mtllib ... are not needed
  }
  if (in.bad()) fail(path, "read error");
  if (max_line > 0 && static_cast<size_t>(max_index) >= mesh.vertices.size())
    fail(where(max_line), "face vertex " + std::to_string(int64_t(max_index) + 1) +
                              " is out of range (" + std::to_string(mesh.vertices.size()) +
                              " vertices)");
  return mesh;
}

std::string input_file_problem(const std::string& path, uint64_t max_bytes) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) return "cannot open (No such file or directory)";
  if (fs::is_directory(st)) return "is a folder, not a file";
  if (!fs::is_regular_file(st)) return "is not a regular file";
  const uintmax_t size = fs::file_size(path, ec);
  if (ec) return "cannot read its size (" + ec.message() + ")";
  if (size > max_bytes)
    return "is " + std::to_string(size) + " bytes, more than the " + std::to_string(max_bytes) +
           " an input may have";
  return "";
}

Mesh read_mesh(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".ply") return read_ply_mesh(path);
  if (ext == ".obj") return read_obj(path);
  fail(path, "unsupported mesh format '" + ext + "' (expected .ply or .obj)");
}

void write_obj(const std::string& path, const Mesh& mesh) {
  write_file_atomically(path, [&](std::FILE* f) {
    for (const Vec3& v : mesh.vertices)
      if (std::fprintf(f, "v %.9g %.9g %.9g\n", v.x, v.y, v.z) < 0) return false;
    for (const auto& t : mesh.triangles)
      if (std::fprintf(f, "f %d %d %d\n", t[0] + 1, t[1] + 1, t[2] + 1) < 0) return false;
    return true;
  });
}

}  // namespace grains
