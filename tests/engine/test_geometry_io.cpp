#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "engine/geometry_io.h"
#include "engine/particles.h"

using namespace grains;
namespace fs = std::filesystem;

namespace {

// A fresh folder under the system temp dir, removed at the end of the test.
struct TempDir {
  fs::path dir;
  TempDir() {
    static std::atomic<int> counter{0};
    std::random_device rd;
    dir = fs::temp_directory_path() /
          ("grains_geomio_" + std::to_string(rd()) + "_" + std::to_string(counter++));
    fs::create_directories(dir);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  std::string file(const std::string& name) const { return (dir / name).string(); }
};

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<std::string> header_lines(const std::string& path) {
  std::string data = read_bytes(path);
  size_t end = data.find("end_header\n");
  REQUIRE(end != std::string::npos);
  std::vector<std::string> lines;
  std::istringstream in(data.substr(0, end + 10));
  std::string line;
  while (std::getline(in, line)) lines.push_back(line);
  return lines;
}

bool same_bits(const float* a, const float* b, size_t n) {
  // an empty array's data() may be null, which memcmp must not get even for 0 bytes
  return n == 0 || std::memcmp(a, b, n * sizeof(float)) == 0;
}

// Big-endian binary writer for hand-made test files.
struct BigEndian {
  std::string bytes;
  template <class T>
  void put(T v) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    for (size_t k = sizeof(T); k-- > 0;) bytes.push_back(static_cast<char>(b[k]));
  }
};

// A store with a mix of attributes, a deleted point (so ids have a gap) and constraints.
ParticleStore sample_store() {
  ParticleStore s;
  s.add_points(6);
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> u(-3.0f, 3.0f);
  float* P = s.v3("P");
  float* v = s.v3("v");
  float* ps = s.f("pscale");
  float* temp = s.f("temperature");
  float* tp = s.v3("targetP");
  for (size_t k = 0; k < s.size(); ++k) {
    for (int c = 0; c < 3; ++c) {
      P[3 * k + c] = u(rng);
      v[3 * k + c] = u(rng);
      tp[3 * k + c] = u(rng);
    }
    ps[k] = 0.01f + 0.001f * static_cast<float>(k);
    temp[k] = u(rng);
  }
  s.set_group("pinned", 2, true);
  s.set_group("pinned", 4, true);
  s.i("streamid")[3] = 7;
  s.add_prim(0, 1);
  s.add_prim(2, 5);
  s.add_prim(4, 3);
  float* rest = s.prim_f("restlength");
  float* strain = s.prim_f("strain");
  float* strength = s.prim_f("strength");
  for (size_t p = 0; p < s.prim_count(); ++p) {
    rest[p] = 0.1f * static_cast<float>(p + 1) + 1e-7f;
    strain[p] = u(rng);
    strength[p] = 0.5f;
  }
  std::vector<uint8_t> dead(s.size(), 0);
  dead[1] = 1;  // removes prim (0,1) too
  s.remove_points(dead);
  return s;
}

}  // namespace

TEST_CASE("write_ply then read_ply round-trips points, attributes and edges bit-exactly",
          "[geometry_io]") {
  TempDir tmp;
  ParticleStore s = sample_store();
  REQUIRE(s.size() == 5);
  REQUIRE(s.prim_count() == 2);
  const std::string path = tmp.file("frame_0001.ply");
  write_ply(path, s,
            {"temperature", "group_pinned", "targetP", "streamid", "P", "id", "friction",
             "temperature"});

  ParticleStore r = read_ply(path);
  REQUIRE(r.size() == s.size());
  CHECK(same_bits(r.v3_if("P"), s.v3_if("P"), 15));
  CHECK(same_bits(r.v3_if("v"), s.v3_if("v"), 15));
  CHECK(same_bits(r.f_if("pscale"), s.f_if("pscale"), 5));
  REQUIRE(r.f_if("temperature"));
  CHECK(same_bits(r.f_if("temperature"), s.f_if("temperature"), 5));
  REQUIRE(r.v3_if("targetP"));
  CHECK(same_bits(r.v3_if("targetP"), s.v3_if("targetP"), 15));
  for (size_t k = 0; k < 5; ++k) {
    CHECK(r.i_if("id")[k] == s.i_if("id")[k]);
    CHECK(r.in_group("pinned", k) == s.in_group("pinned", k));
    CHECK(r.i_if("streamid")[k] == s.i_if("streamid")[k]);
    // friction was requested but not in the store: written with its documented default
    CHECK(r.f_if("friction")[k] == 1.0f);
  }
  CHECK(r.i_if("id")[1] == 2);  // the gap left by the deleted point survives
  CHECK(r.next_id() == 6);
  // only what was asked for is written
  CHECK_FALSE(r.has("force_x"));

  REQUIRE(r.prim_count() == 2);
  CHECK(r.prim_points() == s.prim_points());
  CHECK(same_bits(r.prim_f_if("restlength"), s.prim_f_if("restlength"), 2));
  CHECK(same_bits(r.prim_f_if("strain"), s.prim_f_if("strain"), 2));
  CHECK(r.prim_f_if("strength") == nullptr);  // write_ply writes restlength and strain only
}

TEST_CASE("write_ply header is exactly DESIGN section 6", "[geometry_io]") {
  TempDir tmp;
  ParticleStore s = sample_store();
  const std::string path = tmp.file("frame_0002.ply");
  write_ply(path, s, {"temperature", "group_pinned", "targetP", "pscale", "v"});
  const std::vector<std::string> expected = {
      "ply",
      "format binary_little_endian 1.0",
      "element vertex 5",
      "property float x",
      "property float y",
      "property float z",
      "property float vx",
      "property float vy",
      "property float vz",
      "property float pscale",
      "property int id",
      "property float temperature",
      "property int group_pinned",
      "property float targetP_x",
      "property float targetP_y",
      "property float targetP_z",
      "element edge 2",
      "property int vertex1",
      "property int vertex2",
      "property float restlength",
      "property float strain",
      "end_header",
  };
  CHECK(header_lines(path) == expected);
  // header + 5 * (8 + 5) * 4 bytes + 2 * 4 * 4 bytes
  size_t header_bytes = 0;
  for (const auto& l : expected) header_bytes += l.size() + 1;
  CHECK(fs::file_size(path) == header_bytes + 5 * 13 * 4 + 2 * 16);
}

TEST_CASE("write_ply writes through a temporary name and leaves no .tmp behind", "[geometry_io]") {
  TempDir tmp;
  ParticleStore s = sample_store();
  const std::string path = tmp.file("frame_0003.ply");
  write_text(path, "old contents");
  write_ply(path, s, {});
  CHECK_FALSE(fs::exists(path + ".tmp"));
  ParticleStore r = read_ply(path);
  CHECK(r.size() == 5);
  size_t n = 0;
  for (const auto& e : fs::directory_iterator(tmp.dir)) {
    (void)e;
    ++n;
  }
  CHECK(n == 1);

  // unwritable destination: a WriteError naming the file and the system's reason
  const std::string bad = tmp.file("no_such_dir/frame.ply");
  try {
    write_ply(bad, s, {});
    FAIL("expected WriteError");
  } catch (const WriteError& e) {
    CHECK(std::string(e.what()) == bad + ": cannot write (No such file or directory)");
  }
}

TEST_CASE("write_ply rejects an attribute it cannot write", "[geometry_io]") {
  TempDir tmp;
  ParticleStore s = sample_store();
  const std::string path = tmp.file("f.ply");
  try {
    write_ply(path, s, {"temperature", "no_such_attr"});
    FAIL("expected GeometryError");
  } catch (const GeometryError& e) {
    CHECK_THAT(e.what(), Catch::Contains("no_such_attr"));
  }
  CHECK_FALSE(fs::exists(path));
  CHECK_FALSE(fs::exists(path + ".tmp"));
}

TEST_CASE("write_ply_all writes every attribute and primitive attribute", "[geometry_io]") {
  TempDir tmp;
  ParticleStore s = sample_store();
  const std::string path = tmp.file("all.ply");
  write_ply_all(path, s);
  std::vector<std::string> h = header_lines(path);
  // after the fixed eight, every other attribute in name order
  std::vector<std::string> vertex_props(h.begin() + 11, h.begin() + 11 + 17);
  CHECK(vertex_props == std::vector<std::string>{
                            "property float force_x", "property float force_y",
                            "property float force_z", "property int group_pinned",
                            "property int ispbd", "property float mass",
                            "property int streamid", "property float targetP_x",
                            "property float targetP_y", "property float targetP_z",
                            "property float temperature", "element edge 2",
                            "property int vertex1", "property int vertex2",
                            "property float restlength", "property float strain",
                            "property float strength"});
  ParticleStore r = read_ply(path);
  for (const auto& [name, a] : s.attributes()) {
    const Attribute* b = r.find(name);
    REQUIRE(b);
    REQUIRE(b->type == a.type);
    CHECK(b->i == a.i);
    CHECK(same_bits(b->f.data(), a.f.data(), a.f.size()));
  }
  CHECK(r.attributes().size() == s.attributes().size());
  REQUIRE(r.prim_count() == 2);
  for (const auto& [name, values] : s.prim_attributes()) {
    REQUIRE(r.prim_f_if(name));
    CHECK(same_bits(r.prim_f_if(name), values.data(), values.size()));
  }
}

TEST_CASE("read_ply reads ascii with comments, other elements and missing ids", "[geometry_io]") {
  TempDir tmp;
  const std::string path = tmp.file("in.ply");
  write_text(path,
             "ply\r\n"
             "format ascii 1.0\r\n"
             "comment made by hand\r\n"
             "obj_info nothing\r\n"
             "element vertex 3\r\n"
             "property double x\r\n"
             "property float y\r\n"
             "property float z\r\n"
             "property float pscale\r\n"
             "property uchar group_top\r\n"
             "property float rest_x\r\n"
             "property float rest_y\r\n"
             "property float rest_z\r\n"
             "property float heat_x\r\n"
             "element face 2\r\n"
             "property list uchar int vertex_indices\r\n"
             "element edge 2\r\n"
             "property int vertex1\r\n"
             "property int vertex2\r\n"
             "property float stiffness\r\n"
             "end_header\r\n"
             "0 0 0 0.1 1 1 2 3 7\r\n"
             "3 4 0 0.2 0 4 5 6 8\r\n"
             "1e0 -2.5 +1 0.3 1 7 8 9 9\r\n"
             "3 0 1 2\r\n"
             "4 0 1 2 0\r\n"
             "0 1 0.5\r\n"
             "1 2 0.25\r\n");
  ParticleStore r = read_ply(path);
  REQUIRE(r.size() == 3);
  const float* P = r.v3_if("P");
  CHECK(P[3] == 3.0f);
  CHECK(P[4] == 4.0f);
  CHECK(P[6] == 1.0f);
  CHECK(P[7] == -2.5f);
  CHECK(P[8] == 1.0f);
  CHECK(r.f_if("pscale")[2] == 0.3f);
  CHECK(r.in_group("top", 0));
  CHECK_FALSE(r.in_group("top", 1));
  CHECK(r.v3_if("rest")[5] == 6.0f);
  CHECK(r.f_if("heat_x")[2] == 9.0f);  // a lone _x is a float
  CHECK(r.i_if("id")[0] == 0);
  CHECK(r.i_if("id")[2] == 2);
  CHECK(r.next_id() == 3);
  CHECK(r.v3_if("v")[0] == 0.0f);
  REQUIRE(r.prim_count() == 2);
  CHECK(r.prim_points() == std::vector<int32_t>{0, 1, 1, 2});
  CHECK(r.prim_f_if("stiffness")[1] == 0.25f);
  // no restlength: the distance at load
  CHECK(r.prim_f_if("restlength")[0] == Approx(5.0f));
}

TEST_CASE("read_ply reads big-endian binary with mixed types and list elements",
          "[geometry_io]") {
  TempDir tmp;
  const std::string path = tmp.file("be.ply");
  std::string header =
      "ply\n"
      "format binary_big_endian 1.0\n"
      "element vertex 2\n"
      "property float64 x\n"
      "property float32 y\n"
      "property double z\n"
      "property uint id\n"
      "property short temperature_int\n"
      "property float vx\n"
      "property float vy\n"
      "property float vz\n"
      "element face 1\n"
      "property list uchar uint vertex_indices\n"
      "property ushort material\n"
      "element edge 1\n"
      "property int32 vertex1\n"
      "property int32 vertex2\n"
      "property float restlength\n"
      "end_header\n";
  BigEndian b;
  b.put<double>(1.5);
  b.put<float>(-2.25f);
  b.put<double>(3.0);
  b.put<uint32_t>(10);
  b.put<int16_t>(-300);
  b.put<float>(0.5f);
  b.put<float>(0.25f);
  b.put<float>(-1.0f);
  b.put<double>(0.0);
  b.put<float>(1.0f);
  b.put<double>(2.0);
  b.put<uint32_t>(40);
  b.put<int16_t>(12);
  b.put<float>(0.0f);
  b.put<float>(0.0f);
  b.put<float>(0.0f);
  // face: 4 indices then a ushort
  b.bytes.push_back(4);
  for (uint32_t k : {0u, 1u, 0u, 1u}) b.put<uint32_t>(k);
  b.put<uint16_t>(3);
  b.put<int32_t>(1);
  b.put<int32_t>(0);
  b.put<float>(0.75f);
  write_text(path, header + b.bytes);

  ParticleStore r = read_ply(path);
  REQUIRE(r.size() == 2);
  const float* P = r.v3_if("P");
  CHECK(P[0] == 1.5f);
  CHECK(P[1] == -2.25f);
  CHECK(P[2] == 3.0f);
  CHECK(P[5] == 2.0f);
  CHECK(r.v3_if("v")[1] == 0.25f);
  CHECK(r.i_if("id")[0] == 10);
  CHECK(r.i_if("id")[1] == 40);
  CHECK(r.next_id() == 41);
  REQUIRE(r.i_if("temperature_int"));
  CHECK(r.i_if("temperature_int")[0] == -300);
  REQUIRE(r.prim_count() == 1);
  CHECK(r.prim_points() == std::vector<int32_t>{1, 0});
  CHECK(r.prim_f_if("restlength")[0] == 0.75f);

  // the same file as a mesh: vertices and the quad as two triangles
  Mesh m = read_mesh(path);
  REQUIRE(m.vertices.size() == 2);
  CHECK(m.vertices[1].z == 2.0f);
  CHECK(m.triangles.size() == 2);
}

namespace {
std::string error_of(const std::string& path) {
  try {
    read_ply(path);
  } catch (const GeometryError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST_CASE("read_ply errors name the file and the problem", "[geometry_io]") {
  TempDir tmp;
  const std::string missing = tmp.file("missing.ply");
  std::string e = error_of(missing);
  CHECK(e.rfind(missing + ": ", 0) == 0);

  const std::string head = "ply\nformat ascii 1.0\nelement vertex 1\n";
  const std::string nox = tmp.file("nox.ply");
  write_text(nox, head + "property float y\nproperty float z\nend_header\n1 2\n");
  e = error_of(nox);
  CHECK(e.rfind(nox + ": ", 0) == 0);
  CHECK_THAT(e, Catch::Contains("x/y/z"));

  const std::string intps = tmp.file("intpscale.ply");
  write_text(intps, head +
                        "property float x\nproperty float y\nproperty float z\n"
                        "property int pscale\nend_header\n1 2 3 4\n");
  CHECK(error_of(intps) ==
        intps + ": vertex property 'pscale' is int, but pscale is a float attribute");

  const std::string lone = tmp.file("lone.ply");
  write_text(lone, head +
                       "property float x\nproperty float y\nproperty float z\n"
                       "property float targetP\nend_header\n1 2 3 4\n");
  CHECK(error_of(lone) ==
        lone + ": vertex property 'targetP' is float, but targetP is a vector attribute");

  const std::string fid = tmp.file("floatid.ply");
  write_text(fid, head +
                      "property float x\nproperty float y\nproperty float z\n"
                      "property float id\nend_header\n1 2 3 4\n");
  CHECK(error_of(fid) == fid + ": vertex property 'id' is float, but id is an int attribute");

  const std::string range = tmp.file("range.ply");
  write_text(range,
             "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
             "property float z\nelement edge 1\nproperty int vertex1\nproperty int vertex2\n"
             "end_header\n0 0 0\n1 1 1\n0 2\n");
  e = error_of(range);
  CHECK(e.rfind(range + ": ", 0) == 0);
  CHECK_THAT(e, Catch::Contains("out of range"));

  const std::string dup = tmp.file("dup.ply");
  write_text(dup, "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                  "property float z\nproperty int id\nend_header\n0 0 0 5\n1 1 1 5\n");
  CHECK_THAT(error_of(dup), Catch::Contains("duplicate point id 5"));

  const std::string notply = tmp.file("notply.ply");
  write_text(notply, "hello\n");
  CHECK(error_of(notply).rfind(notply + ": ", 0) == 0);

  const std::string noend = tmp.file("noend.ply");
  write_text(noend, "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n");
  CHECK_THAT(error_of(noend), Catch::Contains("end_header"));

  const std::string badtype = tmp.file("badtype.ply");
  write_text(badtype, "ply\nformat ascii 1.0\nelement vertex 0\nproperty quad x\nend_header\n");
  CHECK_THAT(error_of(badtype), Catch::Contains("unknown property type"));

  const std::string asciitrunc = tmp.file("asciitrunc.ply");
  write_text(asciitrunc, "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
                         "property float y\nproperty float z\nend_header\n0 0 0\n1 1\n");
  CHECK_THAT(error_of(asciitrunc), Catch::Contains("truncated"));
}

TEST_CASE("read_ply detects truncated binary data", "[geometry_io]") {
  TempDir tmp;
  ParticleStore s = sample_store();
  const std::string full = tmp.file("full.ply");
  write_ply(full, s, {"temperature"});
  const std::string data = read_bytes(full);
  for (size_t cut : {size_t(1), size_t(7), size_t(40), size_t(100)}) {
    const std::string path = tmp.file("cut" + std::to_string(cut) + ".ply");
    write_text(path, data.substr(0, data.size() - cut));
    std::string e = error_of(path);
    CHECK(e.rfind(path + ": ", 0) == 0);
    CHECK_THAT(e, Catch::Contains("truncated"));
  }
  // a header that promises far more points than the file holds fails without allocating them
  const std::string huge = tmp.file("huge.ply");
  write_text(huge, "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000000\n"
                   "property float x\nproperty float y\nproperty float z\nend_header\n");
  CHECK_THAT(error_of(huge), Catch::Contains("truncated") || Catch::Contains("too many"));
}

TEST_CASE("read_obj reads polygons, slash forms and negative indices", "[geometry_io]") {
  TempDir tmp;
  const std::string path = tmp.file("mesh.obj");
  write_text(path,
             "# a quad and a triangle\r\n"
             "mtllib x.mtl\n"
             "o thing\n"
             "v 0 0 0\n"
             "v 1 0 0\n"
             "v 1 1 0\n"
             "v 0 1 0 1.0\n"
             "vt 0 0\n"
             "vn 0 0 1\n"
             "g side\n"
             "s off\n"
             "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
             "v 0.5 0.5 1e0\n"
             "f -1//1 -4//1 -3//1   # comment\n"
             "f 1/1 3/1 5/1\n"
             "l 1 2\n");
  Mesh m = read_obj(path);
  REQUIRE(m.vertices.size() == 5);
  CHECK(m.vertices[4].z == 1.0f);
  REQUIRE(m.triangles.size() == 4);
  CHECK(m.triangles[0] == std::array<int, 3>{0, 1, 2});
  CHECK(m.triangles[1] == std::array<int, 3>{0, 2, 3});
  CHECK(m.triangles[2] == std::array<int, 3>{4, 1, 2});
  CHECK(m.triangles[3] == std::array<int, 3>{0, 2, 4});

  Mesh m2 = read_mesh(path);
  CHECK(m2.triangles.size() == 4);

  const std::string bad = tmp.file("bad.obj");
  write_text(bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
  try {
    read_obj(bad);
    FAIL("expected GeometryError");
  } catch (const GeometryError& e) {
    CHECK(std::string(e.what()).rfind(bad + ":4: ", 0) == 0);
  }
  const std::string badv = tmp.file("badv.obj");
  write_text(badv, "v 0 0 0\nv 1 zero 0\n");
  try {
    read_obj(badv);
    FAIL("expected GeometryError");
  } catch (const GeometryError& e) {
    CHECK(std::string(e.what()).rfind(badv + ":2: ", 0) == 0);
  }
  const std::string neg = tmp.file("neg.obj");
  write_text(neg, "v 0 0 0\nf -1 -2 -3\n");
  CHECK_THROWS_AS(read_obj(neg), GeometryError);
  CHECK_THROWS_AS(read_obj(tmp.file("missing.obj")), GeometryError);
  CHECK_THROWS_AS(read_mesh(tmp.file("mesh.stl")), GeometryError);
}

TEST_CASE("large frames round-trip", "[geometry_io]") {
  TempDir tmp;
  ParticleStore s;
  s.add_points(200000);
  float* P = s.v3("P");
  for (size_t k = 0; k < 3 * s.size(); ++k) P[k] = static_cast<float>(k) * 1e-3f;
  float* t = s.f("temperature");
  for (size_t k = 0; k < s.size(); ++k) t[k] = static_cast<float>(k % 97);
  for (int32_t k = 0; k + 1 < 200000; k += 2) s.add_prim(k, k + 1);
  const std::string path = tmp.file("big.ply");
  auto t0 = std::chrono::steady_clock::now();
  write_ply(path, s, {"temperature", "targetP"});
  auto t1 = std::chrono::steady_clock::now();
  ParticleStore r = read_ply(path);
  auto t2 = std::chrono::steady_clock::now();
  REQUIRE(r.size() == s.size());
  CHECK(same_bits(r.v3_if("P"), s.v3_if("P"), 3 * s.size()));
  CHECK(same_bits(r.f_if("temperature"), s.f_if("temperature"), s.size()));
  CHECK(r.prim_points() == s.prim_points());
  CHECK(r.next_id() == 200000);
  using ms = std::chrono::duration<double, std::milli>;
  const double write_ms = ms(t1 - t0).count(), read_ms = ms(t2 - t1).count();
  WARN("200k points: write " << write_ms << " ms, read " << read_ms << " ms");
}
