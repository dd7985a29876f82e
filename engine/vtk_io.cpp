// VTK XML frames and collections. See vtk_io.h.
//
// A .vtp is an XML header that describes every array and its offset, then one raw block per
// array (a 64-bit byte count, then the values) after `_` in AppendedData: the arrays are written
// straight from the store, with no encoding, the way VTK's own writer does with raw appended
// data. Only the vertex and line cells' indices and the defaults of missing attributes are made
// here.
#include "engine/vtk_io.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <set>

#include "engine/geometry_io.h"

namespace grains {

namespace {

// Text for an XML attribute value.
std::string xml_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string number(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

// One array of the appended data: its XML description and its bytes, read from the store in
// place (`data`) or made here (`owned`; moving a Block keeps the bytes where they are).
struct Block {
  std::string name, type;  // type: Float32, Int32 or Int64
  int components = 1;
  const void* data = nullptr;
  uint64_t bytes = 0;
  std::vector<unsigned char> owned;
};

template <class T>
Block view(std::string name, const char* type, int components, const std::vector<T>& v) {
  Block b;
  b.name = std::move(name);
  b.type = type;
  b.components = components;
  b.data = v.data();
  b.bytes = v.size() * sizeof(T);
  return b;
}

template <class T>
Block made(std::string name, const char* type, int components, const std::vector<T>& v) {
  Block b;
  b.name = std::move(name);
  b.type = type;
  b.components = components;
  b.owned.resize(v.size() * sizeof(T));
  if (!v.empty()) std::memcpy(b.owned.data(), v.data(), b.owned.size());
  b.data = b.owned.data();
  b.bytes = b.owned.size();
  return b;
}

// A point attribute as the PLY frame carries it: from the store, or else its documented default
// for every point. Throws GeometryError for one that is neither (the loader refuses those).
Block point_array(const std::string& path, const ParticleStore& pts, const std::string& name) {
  const size_t n = pts.size();
  if (const Attribute* a = pts.find(name)) {
    switch (a->type) {
      case AttribType::Float: return view(name, "Float32", 1, a->f);
      case AttribType::Int: return view(name, "Int32", 1, a->i);
      case AttribType::Vec3: return view(name, "Float32", 3, a->f);
    }
  }
  const AttribDefault* d = find_known_attribute(name);
  if (!d)
    throw GeometryError(path + ": cannot write attribute '" + name +
                        "': not in the store and not a known attribute");
  switch (d->type) {
    case AttribType::Float: return made(name, "Float32", 1, std::vector<float>(n, d->value[0]));
    case AttribType::Int:
      return made(name, "Int32", 1, std::vector<int32_t>(n, static_cast<int32_t>(d->value[0])));
    case AttribType::Vec3: {
      std::vector<float> v(3 * n);
      for (size_t k = 0; k < v.size(); ++k) v[k] = d->value[k % 3];
      return made(name, "Float32", 3, v);
    }
  }
  return {};
}

// The PLY's fixed columns, checked as write_ply checks them: P and v vectors (zero when absent),
// pscale a float, id an int that must exist.
void check_fixed(const std::string& path, const ParticleStore& pts) {
  for (const char* name : {"P", "v"})
    if (const Attribute* a = pts.find(name); a && a->type != AttribType::Vec3)
      throw GeometryError(path + ": cannot write: " + name + " is not a vector attribute");
  if (const Attribute* a = pts.find("pscale"); a && a->type != AttribType::Float)
    throw GeometryError(path + ": cannot write: pscale is not a float attribute");
  const Attribute* id = pts.find("id");
  if (!id || id->type != AttribType::Int)
    throw GeometryError(path + ": cannot write: the store has no int id attribute");
}

Block vector_or_zero(const std::string& path, const ParticleStore& pts, const char* name) {
  if (pts.find(name)) return point_array(path, pts, name);
  return made(name, "Float32", 3, std::vector<float>(3 * pts.size(), 0.0f));
}

bool is_fixed(const std::string& name) {
  return name == "P" || name == "v" || name == "pscale" || name == "id";
}

// A primitive attribute as a cell array: NaN on the n vertex cells, then one value per line.
Block cell_array(const std::string& name, size_t verts, const ParticleStore& pts) {
  std::vector<float> v(verts + pts.prim_count(), std::numeric_limits<float>::quiet_NaN());
  const float* p = pts.prim_f_if(name);
  for (size_t k = 0; k < pts.prim_count(); ++k) v[verts + k] = p ? p[k] : 0.0f;
  return made(name, "Float32", 1, v);
}

// Writes `text` then the blocks (each a 64-bit byte count and its bytes) then `tail` to PATH,
// through PATH.tmp (write_file_atomically).
void write_with_blocks(const std::string& path, const std::string& text,
                       const std::vector<const Block*>& blocks, const std::string& tail) {
  write_file_atomically(path, [&](std::FILE* f) {
    bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
    for (const Block* b : blocks) {
      if (!ok) break;
      const uint64_t bytes = b->bytes;
      ok = std::fwrite(&bytes, sizeof bytes, 1, f) == 1 &&
           (bytes == 0 || std::fwrite(b->data, 1, bytes, f) == bytes);
    }
    return ok && std::fwrite(tail.data(), 1, tail.size(), f) == tail.size();
  });
}

}  // namespace

void write_vtp(const std::string& path, const ParticleStore& pts,
               const std::vector<std::string>& attributes, bool all, double time) {
  check_fixed(path, pts);
  const size_t n = pts.size(), m = pts.prim_count();

  // point data: the PLY's vertex columns, in its order
  std::vector<Block> point;
  point.push_back(vector_or_zero(path, pts, "v"));
  point.push_back(point_array(path, pts, "pscale"));
  point.push_back(point_array(path, pts, "id"));
  std::set<std::string> seen;
  if (all) {
    for (const auto& [name, a] : pts.attributes())
      if (!is_fixed(name)) point.push_back(point_array(path, pts, name));
  } else {
    for (const std::string& name : attributes)
      if (!is_fixed(name) && seen.insert(name).second)
        point.push_back(point_array(path, pts, name));
  }

  // cell data: the PLY's edge columns
  std::vector<Block> cell;
  cell.push_back(cell_array("restlength", n, pts));
  cell.push_back(cell_array("strain", n, pts));
  if (all)
    for (const auto& [name, values] : pts.prim_attributes())
      if (name != "restlength" && name != "strain") cell.push_back(cell_array(name, n, pts));

  // geometry: the points, a vertex cell per point and a line cell per primitive
  Block points = vector_or_zero(path, pts, "P");
  points.name = "Points";
  std::vector<int64_t> index(n), ends(n);
  for (size_t k = 0; k < n; ++k) index[k] = static_cast<int64_t>(k), ends[k] = static_cast<int64_t>(k + 1);
  Block vert_conn = made("connectivity", "Int64", 1, index);
  Block vert_ends = made("offsets", "Int64", 1, ends);
  index.assign(pts.prim_points().begin(), pts.prim_points().end());
  ends.resize(m);
  for (size_t k = 0; k < m; ++k) ends[k] = static_cast<int64_t>(2 * (k + 1));
  Block line_conn = made("connectivity", "Int64", 1, index);
  Block line_ends = made("offsets", "Int64", 1, ends);

  // the header, each array at its offset in the appended data
  std::vector<const Block*> order;
  uint64_t offset = 0;
  auto describe = [&](const Block& b, const std::string& indent) {
    std::string s = indent + "<DataArray type=\"" + b.type + "\" Name=\"" + xml_escape(b.name) +
                    "\"";
    if (b.components > 1) s += " NumberOfComponents=\"" + std::to_string(b.components) + "\"";
    s += " format=\"appended\" offset=\"" + std::to_string(offset) + "\"/>\n";
    offset += sizeof(uint64_t) + b.bytes;
    order.push_back(&b);
    return s;
  };
  const char* order_name = std::endian::native == std::endian::little ? "LittleEndian" : "BigEndian";
  std::string x = std::string("<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" "
                              "byte_order=\"") + order_name + "\" header_type=\"UInt64\">\n";
  x += "  <PolyData>\n    <FieldData>\n"
       "      <DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" format=\"ascii\">" +
       number(time) + "</DataArray>\n    </FieldData>\n";
  x += "    <Piece NumberOfPoints=\"" + std::to_string(n) + "\" NumberOfVerts=\"" +
       std::to_string(n) + "\" NumberOfLines=\"" + std::to_string(m) +
       "\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">\n";
  x += "      <PointData Scalars=\"pscale\" Vectors=\"v\">\n";
  for (const Block& b : point) x += describe(b, "        ");
  x += "      </PointData>\n      <CellData>\n";
  for (const Block& b : cell) x += describe(b, "        ");
  x += "      </CellData>\n      <Points>\n" + describe(points, "        ") + "      </Points>\n";
  x += "      <Verts>\n" + describe(vert_conn, "        ");
  x += describe(vert_ends, "        ") + "      </Verts>\n";
  x += "      <Lines>\n" + describe(line_conn, "        ");
  x += describe(line_ends, "        ") + "      </Lines>\n";
  x += "    </Piece>\n  </PolyData>\n  <AppendedData encoding=\"raw\">\n   _";
  write_with_blocks(path, x, order, "\n  </AppendedData>\n</VTKFile>\n");
}

void write_pvd(const std::string& path, const std::vector<VtkDataSet>& frames) {
  std::string x =
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" "
      "byte_order=\"LittleEndian\">\n  <Collection>\n";
  for (const VtkDataSet& d : frames)
    x += "    <DataSet timestep=\"" + number(d.time) + "\" group=\"\" part=\"0\" file=\"" +
         xml_escape(d.file) + "\"/>\n";
  x += "  </Collection>\n</VTKFile>\n";
  write_with_blocks(path, x, {}, "");
}

std::vector<VtkDataSet> read_pvd(const std::string& path) {
  std::vector<VtkDataSet> out;
  std::ifstream in(path);
  // the value of attribute `key` in `line`, or false when it has none
  auto value = [](const std::string& line, const std::string& key, std::string& v) {
    const size_t at = line.find(" " + key + "=\"");
    if (at == std::string::npos) return false;
    const size_t from = at + key.size() + 3, to = line.find('"', from);
    if (to == std::string::npos) return false;
    v = line.substr(from, to - from);
    return true;
  };
  for (std::string line; std::getline(in, line);) {
    std::string t, file;
    if (line.find("<DataSet ") == std::string::npos || !value(line, "timestep", t) ||
        !value(line, "file", file))
      continue;
    char* end = nullptr;
    const double time = std::strtod(t.c_str(), &end);
    if (end == t.c_str() || file.empty() || file.find('&') != std::string::npos) continue;
    out.push_back({time, file});
  }
  return out;
}

}  // namespace grains
