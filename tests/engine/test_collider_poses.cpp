// collider_poses.csv (engine/collider_poses.h, docs/output-format.md): what the run writes reads
// back bit for bit, and a damaged file is refused with its line, never read half.
#include <catch2/catch.hpp>

#include <cstring>
#include <string>
#include <vector>

#include "engine/collider_poses.h"
#include "engine/geometry_io.h"
#include "tests/support/support.h"

using namespace grains;

namespace {

// One collider of each shape, with poses no decimal writes exactly.
std::vector<ColliderState> one_of_each() {
  std::vector<ColliderState> out;
  const ShapeKind kinds[] = {ShapeKind::Plane, ShapeKind::Box, ShapeKind::Sphere,
                             ShapeKind::Torus, ShapeKind::Capsule};
  for (int k = 0; k < 5; ++k) {
    ColliderState c;
    c.name = std::string("c") + std::to_string(k);
    c.shape.kind = kinds[k];
    c.shape.size = {0.1f * (k + 1), 1.0f / 3, 2e-7f};
    c.shape.radius = 0.7f / (k + 1);
    c.shape.tube = 1.0f / 7;
    c.shape.height = k * 0.3f;
    c.pose = Pose::from_trs({0.1f * k, -1.0f / 3, 1e5f / 7}, {10.0f * k, 33.3f, -71}, 1.1f);
    out.push_back(c);
  }
  return out;
}

bool same_bits(const ColliderState& a, const ColliderState& b) {
  return a.name == b.name && a.shape.kind == b.shape.kind &&
         std::memcmp(&a.shape.size, &b.shape.size, sizeof(Vec3)) == 0 &&
         a.shape.radius == b.shape.radius && a.shape.tube == b.shape.tube &&
         a.shape.height == b.shape.height && std::memcmp(a.pose.R, b.pose.R, sizeof a.pose.R) == 0 &&
         std::memcmp(&a.pose.t, &b.pose.t, sizeof(Vec3)) == 0 && a.pose.s == b.pose.s;
}

}  // namespace

TEST_CASE("collider poses read back bit for bit, frame by frame", "[collider_poses][geometry_io]") {
  const std::string dir = test::temp_dir("poses");
  const std::vector<ColliderState> cs = one_of_each();
  std::vector<ColliderState> later = cs;
  later[2].pose.t.y += 0.25f;
  const std::string path = test::write_file(
      dir, kColliderPosesFile,
      collider_poses_header() + collider_poses_rows(1, 1 / 24.0, cs) +
          collider_poses_rows(2, 2 / 24.0, later));
  const auto frames = read_collider_poses(path);
  REQUIRE(frames.size() == 2);
  REQUIRE(frames.at(1).size() == cs.size());
  for (size_t k = 0; k < cs.size(); ++k) {
    INFO("collider " << k);
    CHECK(same_bits(frames.at(1)[k], cs[k]));
    CHECK(same_bits(frames.at(2)[k], later[k]));
  }
  // the header alone: a solver without colliders
  CHECK(read_collider_poses(test::write_file(dir, "empty.csv", collider_poses_header())).empty());
}

TEST_CASE("a damaged collider_poses.csv is refused with its line and what is wrong",
          "[collider_poses][geometry_io]") {
  const std::string dir = test::temp_dir("poses_bad");
  const std::string good = collider_poses_rows(3, 0.125, {one_of_each()[1]});  // one box row
  auto with_field = [&](int k, const std::string& text) {
    std::vector<std::string> f = test::split(good.substr(0, good.size() - 1), ',');
    f[k] = text;
    std::string row;
    for (const auto& x : f) row += (row.empty() ? "" : ",") + x;
    return row + "\n";
  };
  struct Case {
    std::string text, message;
  };
  const std::string h = collider_poses_header();
  for (const Case& c : std::vector<Case>{
           {"", ":1: not a collider_poses.csv"},
           {"frame,time\n" + good, ":1: not a collider_poses.csv"},
           {"ply\nformat ascii 1.0\n", ":1: not a collider_poses.csv"},
           {h + "3,0.125,box\n", ":2: 3 fields, expected 23"},
           {h + good.substr(0, good.size() - 1) + ",7\n", ":2: 24 fields, expected 23"},
           {h + good + with_field(19, "nan"), ":3: tx 'nan' is not a finite number"},
           {h + with_field(22, "1e39"), ":2: scale '1e39' is not a finite number"},
           {h + with_field(22, "0"), ":2: scale must be positive"},
           {h + with_field(7, "-1"), ":2: radius must not be negative"},
           {h + with_field(10, ""), ":2: r00 '' is not a finite number"},
           {h + with_field(3, "cone"), ":2: unknown shape 'cone'"},
           {h + with_field(2, ""), ":2: the collider has no name"},
           {h + with_field(0, "0"), ":2: frame '0' is not a frame number"},
           {h + with_field(0, "99999999999"), ":2: frame '99999999999' is not a frame number"},
           {h + with_field(0, "-1"), ":2: frame '-1' is not a frame number"},
           {h + with_field(1, "soon"), ":2: time 'soon' is not a finite number"},
       }) {
    const std::string path = test::write_file(dir, kColliderPosesFile, c.text);
    INFO(c.text);
    CHECK_THROWS_WITH(read_collider_poses(path), Catch::Contains(path + c.message));
  }
  CHECK_THROWS_WITH(read_collider_poses(dir + "/none.csv"), Catch::Contains(dir + "/none.csv"));
  CHECK_THROWS_AS(read_collider_poses(dir), GeometryError);  // a folder
}
