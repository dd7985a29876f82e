#include "engine/collider_poses.h"

#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "engine/geometry_io.h"
#include "engine/mesh_shape.h"

namespace grains {

namespace {

constexpr int kFields = 23;

[[noreturn]] void fail(const std::string& where, const std::string& what) {
  throw GeometryError(where + ": " + what);
}

// The whole of `text` as a finite float, or false.
bool parse_float(const std::string& text, float& out) {
  if (text.empty() || std::isspace(static_cast<unsigned char>(text[0]))) return false;
  char* end = nullptr;
  errno = 0;
  out = std::strtof(text.c_str(), &end);
  return end == text.c_str() + text.size() && errno != ERANGE && std::isfinite(out);
}

}  // namespace

std::string collider_mesh_file(const std::string& name) { return "collider_" + name + ".obj"; }

std::string collider_poses_header() {
  return "frame,time,collider,shape,size_x,size_y,size_z,radius,tube,height,"
         "r00,r01,r02,r10,r11,r12,r20,r21,r22,tx,ty,tz,scale\n";
}

std::string collider_poses_rows(int frame, double time,
                                const std::vector<ColliderState>& colliders) {
  std::string rows;
  char buf[512];
  for (const ColliderState& c : colliders) {
    Shape s = c.shape;
    if (s.kind == ShapeKind::Mesh) {  // its bounding box; the triangles are in their own file
      s.size = s.mesh ? s.mesh->upper() - s.mesh->lower() : Vec3{0, 0, 0};
      s.radius = s.tube = s.height = 0;
    }
    const float* R = c.pose.R;
    std::snprintf(buf, sizeof buf,
                  "%d,%.6g,%s,%s,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,"
                  "%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n",
                  frame, time, c.name.c_str(), shape_name(s.kind), s.size.x, s.size.y, s.size.z,
                  s.radius, s.tube, s.height, R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8],
                  c.pose.t.x, c.pose.t.y, c.pose.t.z, c.pose.s);
    rows += buf;
  }
  return rows;
}

std::map<int, std::vector<ColliderState>> read_collider_poses(const std::string& path) {
  if (std::string bad = input_file_problem(path, kMaxGeometryFileBytes); !bad.empty())
    fail(path, bad);
  std::ifstream in(path);
  if (!in) fail(path, std::string("cannot open (") + std::strerror(errno) + ")");
  std::map<int, std::vector<ColliderState>> frames;
  std::map<std::string, std::shared_ptr<const MeshShape>> meshes;  // by collider name
  const std::string dir = std::filesystem::path(path).parent_path().string();
  std::string line;
  if (!std::getline(in, line) || line + "\n" != collider_poses_header())
    fail(path + ":1", "not a collider_poses.csv (expected the header " +
                          collider_poses_header().substr(0, 40) + "...)");
  size_t line_no = 1;
  std::vector<std::string> f;
  while (std::getline(in, line)) {
    ++line_no;
    const std::string where = path + ":" + std::to_string(line_no);
    if (line.empty()) continue;
    f.clear();
    std::stringstream ss(line);
    std::string item;
    while (std::getline(ss, item, ',')) f.push_back(item);
    if (!line.empty() && line.back() == ',') f.push_back("");
    if (f.size() != kFields)
      fail(where, std::to_string(f.size()) + " fields, expected " + std::to_string(kFields));
    const std::string& digits = f[0];
    if (digits.empty() || digits.size() > 10 ||
        digits.find_first_not_of("0123456789") != std::string::npos ||
        std::stoll(digits) < 1 || std::stoll(digits) > INT_MAX)
      fail(where, "frame '" + digits + "' is not a frame number (1 to 2147483647)");
    ColliderState c;
    c.name = f[2];
    if (c.name.empty()) fail(where, "the collider has no name");
    if (!parse_shape(f[3], c.shape.kind)) fail(where, "unknown shape '" + f[3] + "'");
    float v[19];
    static const char* names[19] = {"size_x", "size_y", "size_z", "radius", "tube", "height",
                                    "r00",    "r01",    "r02",    "r10",    "r11",  "r12",
                                    "r20",    "r21",    "r22",    "tx",     "ty",   "tz",
                                    "scale"};
    for (int k = 0; k < 19; ++k)
      if (!parse_float(f[4 + k], v[k]))
        fail(where, std::string(names[k]) + " '" + f[4 + k] + "' is not a finite number");
    float time = 0;
    if (!parse_float(f[1], time)) fail(where, "time '" + f[1] + "' is not a finite number");
    for (int k = 3; k < 6; ++k)  // what the collider node's parameters also refuse
      if (v[k] < 0) fail(where, std::string(names[k]) + " must not be negative");
    if (!(v[18] > 0)) fail(where, "scale must be positive");
    c.shape.size = {v[0], v[1], v[2]};
    c.shape.radius = v[3];
    c.shape.tube = v[4];
    c.shape.height = v[5];
    for (int k = 0; k < 9; ++k) c.pose.R[k] = v[6 + k];
    c.pose.t = {v[15], v[16], v[17]};
    c.pose.s = v[18];
    c.prev_pose = c.pose;
    if (c.shape.kind == ShapeKind::Mesh) {
      std::shared_ptr<const MeshShape>& mesh = meshes[c.name];
      if (!mesh) {
        const std::string file = (dir.empty() ? "" : dir + "/") + collider_mesh_file(c.name);
        std::string problem;
        mesh = MeshShape::build(read_mesh(file), &problem);
        if (!mesh) fail(file, problem);
      }
      c.shape.mesh = mesh;
    }
    frames[static_cast<int>(std::stoll(digits))].push_back(std::move(c));
  }
  if (in.bad()) fail(path, std::string("cannot read (") + std::strerror(errno) + ")");
  return frames;
}

}  // namespace grains
