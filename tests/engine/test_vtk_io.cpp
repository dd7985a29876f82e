// VTK XML frames and their collection (engine/vtk_io.h, docs/output-format.md), as FrameWriter
// writes them. VTK's own reader checks the same files' contents in tests/clients/check_vtk.py
// (CTest vtk_client); here, the file's own structure and what a killed or resumed run leaves.
#include <catch2/catch.hpp>
#include <cstring>
#include <filesystem>
#include <regex>

#include "engine/frame_writer.h"
#include "engine/vtk_io.h"
#include "tests/support/support.h"

using namespace grains;
namespace fs = std::filesystem;

namespace {

// Four points in a chain of three constraints, with a float, an int and a vector attribute.
ParticleStore chain() {
  ParticleStore pts;
  pts.add_points(4);
  float* P = pts.v3("P");
  for (int k = 0; k < 4; ++k) P[3 * k] = 0.1f * k, P[3 * k + 1] = 1, P[3 * k + 2] = -0.5f * k;
  for (int k = 0; k < 4; ++k) pts.f("mass")[k] = 1.0f + k;
  pts.i("ispbd")[2] = 1;
  for (int k = 0; k < 3; ++k) {
    pts.add_prim(k, k + 1);
    pts.prim_f("restlength")[k] = 0.1f;
    pts.prim_f("strain")[k] = 0.01f * k;
  }
  return pts;
}

// The byte offsets the header gives its arrays, and those the appended blocks (a 64-bit byte
// count, then the bytes) really start at, from `_` to the end of the appended data.
void offsets(const std::string& file, std::vector<uint64_t>& declared, std::vector<uint64_t>& found) {
  const std::regex offset(R"re(offset="(\d+)")re");
  const size_t data = file.find("<AppendedData encoding=\"raw\">");
  REQUIRE(data != std::string::npos);
  const std::string header = file.substr(0, data);
  for (std::sregex_iterator m(header.begin(), header.end(), offset), end; m != end; ++m)
    declared.push_back(std::stoull((*m)[1]));
  const size_t start = file.find('_', data) + 1;
  const size_t stop = file.rfind("\n  </AppendedData>");
  REQUIRE(stop != std::string::npos);
  for (size_t at = start; at < stop;) {
    found.push_back(at - start);
    uint64_t bytes = 0;
    REQUIRE(at + 8 <= stop);
    std::memcpy(&bytes, file.data() + at, 8);
    at += 8 + bytes;
    REQUIRE(at <= stop);
  }
}

}  // namespace

TEST_CASE("a .vtp frame declares every array where its bytes are", "[vtk][output]") {
  const std::string dir = test::temp_dir("vtk_layout");
  const ParticleStore pts = chain();
  write_vtp(dir + "/f.vtp", pts, {"mass", "force", "ispbd", "id"}, false, 0.5);
  CHECK_FALSE(fs::exists(dir + "/f.vtp.tmp"));
  const std::string file = test::read_text(dir + "/f.vtp");
  for (const char* part :
       {"type=\"PolyData\"", "header_type=\"UInt64\"", "NumberOfPoints=\"4\"",
        "NumberOfVerts=\"4\"", "NumberOfLines=\"3\"", "Scalars=\"pscale\" Vectors=\"v\"",
        "Name=\"v\" NumberOfComponents=\"3\"", "type=\"Float32\" Name=\"pscale\"",
        "type=\"Int32\" Name=\"id\"", "type=\"Float32\" Name=\"mass\"",
        "Name=\"force\" NumberOfComponents=\"3\"", "type=\"Int32\" Name=\"ispbd\"",
        "Name=\"restlength\"", "Name=\"strain\"", "Name=\"Points\" NumberOfComponents=\"3\"",
        "Name=\"TimeValue\" NumberOfTuples=\"1\" format=\"ascii\">0.5<"}) {
    INFO(part);
    CHECK(file.find(part) != std::string::npos);
  }
  // id is written once though asked for: it is one of the fixed columns
  CHECK(file.find("Name=\"id\"") == file.rfind("Name=\"id\""));
  std::vector<uint64_t> declared, found;
  offsets(file, declared, found);
  CHECK(declared == found);
  // v pscale id mass force ispbd, restlength strain, Points, two cell arrays of two cell kinds
  CHECK(found.size() == 6 + 2 + 1 + 4);
  // the points are the store's bytes
  const size_t points = file.find('_', file.find("<AppendedData")) + 1 + declared[8];
  uint64_t bytes = 0;
  std::memcpy(&bytes, file.data() + points, 8);
  REQUIRE(bytes == 4 * 3 * sizeof(float));
  CHECK(std::memcmp(file.data() + points + 8, pts.v3_if("P"), bytes) == 0);
}

TEST_CASE("frames.pvd lists each written .vtp with its time, and a resumed run keeps its own",
          "[vtk][output]") {
  const std::string dir = test::temp_dir("vtk_collection");
  const ParticleStore pts = chain();
  FrameStats stats;
  FrameFormats vtp_only{false, true};
  {
    FrameWriter w(dir, {"mass"}, false, vtp_only);
    // a run killed before its first frame leaves an empty, valid collection
    CHECK(read_pvd(dir + "/frames.pvd").empty());
    CHECK_THAT(test::read_text(dir + "/frames.pvd"), Catch::Contains("<Collection>"));
    for (int f = 1; f <= 4; ++f) {
      stats.frame = f;
      stats.time = f / 24.0;
      w.write({f, &pts, &stats, nullptr, f % 2 == 1});  // output.every 2, from frame 1
    }
  }
  CHECK_FALSE(fs::exists(dir + "/frame_0001.ply"));  // vtp only
  std::vector<VtkDataSet> c = read_pvd(dir + "/frames.pvd");
  REQUIRE(c.size() == 2);
  CHECK(c[0].file == "frame_0001.vtp");
  CHECK(c[0].time == 1 / 24.0);  // written with 17 digits: read back exactly
  CHECK(c[1].file == "frame_0003.vtp");
  CHECK(c[1].time == 3 / 24.0);
  CHECK(fs::exists(dir + "/frame_0003.vtp"));
  for (const auto& e : fs::directory_iterator(dir)) CHECK(e.path().extension() != ".tmp");

  // resumed after frame 2: frame 3's file and its entry go, and are written again
  test::write_file(dir, "frame_0005.vtp.tmp", "half a frame");
  FrameWriter w = FrameWriter::continuing(dir, {"mass"}, 2, vtp_only);
  CHECK_FALSE(fs::exists(dir + "/frame_0003.vtp"));
  CHECK_FALSE(fs::exists(dir + "/frame_0005.vtp.tmp"));
  c = read_pvd(dir + "/frames.pvd");
  REQUIRE(c.size() == 1);
  CHECK(c[0].file == "frame_0001.vtp");
  stats.frame = 3;
  stats.time = 3 / 24.0;
  w.write({3, &pts, &stats, nullptr, true});
  c = read_pvd(dir + "/frames.pvd");
  REQUIRE(c.size() == 2);
  CHECK(c[1].file == "frame_0003.vtp");
}

TEST_CASE("output.formats: ply by default, and each format named once", "[vtk][graph]") {
  const char* head = R"({"grains_graph": 1, "name": "f", "nodes": [
    {"name": "src", "type": "source", "params": {}},
    {"name": "s", "type": "solver", "inputs": ["src"], "params": {}}])";
  CHECK(test::graph_from(std::string(head) + "}").output.formats ==
        std::vector<std::string>{"ply"});
  CHECK(test::graph_from(std::string(head) + R"(, "output": {"formats": ["vtp", "ply"]}})")
            .output.formats == std::vector<std::string>{"vtp", "ply"});
  CHECK(FrameFormats::from({"vtp"}).ply == false);
  CHECK(FrameFormats::from({"vtp"}).vtp == true);
  try {
    test::graph_from(std::string(head) + R"(, "output": {"formats": ["ply", "vtk"]}})", "g.json");
    FAIL("an unknown format was accepted");
  } catch (const LoadError& e) {
    CHECK(std::string(e.what()) ==
          "g.json: /output/formats/1: unknown frame format 'vtk': one of \"ply\", \"vtp\"");
  }
}
