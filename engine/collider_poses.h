// The colliders' poses a run wrote, DIR/collider_poses.csv (docs/output-format.md): one row per
// frame and collider with the shape and the pose the simulation used at the frame's end, so that
// a reader (the offline viewer, a user's script) places each collider exactly where the grains
// met it without evaluating the graph again.
//
//   frame,time,collider,shape,size_x,size_y,size_z,radius,tube,height,
//   r00,r01,r02,r10,r11,r12,r20,r21,r22,tx,ty,tz,scale
//
// world = (tx, ty, tz) + scale * R * local, R row-major; the shape in its local frame as
// engine/collider.h describes it. A mesh collider's row gives its local bounding box as size
// and 0 for radius, tube and height; its triangles, in its local frame, are in
// DIR/collider_NAME.obj, written before its first row. Floats are written with 9 significant digits, which read back
// to the same float bit for bit.
#pragma once
#include <map>
#include <string>
#include <vector>

#include "engine/collider.h"

namespace grains {

constexpr const char* kColliderPosesFile = "collider_poses.csv";
// The file beside collider_poses.csv that holds mesh collider NAME's triangles.
std::string collider_mesh_file(const std::string& name);

// The header line, newline included.
std::string collider_poses_header();
// The rows of one frame (frame number, time in s), in the order of `colliders`.
std::string collider_poses_rows(int frame, double time, const std::vector<ColliderState>& colliders);

// Reads a collider_poses.csv: frame number -> its colliders in file order (shape, pose and name;
// prev_pose equals pose). Throws GeometryError naming the file, the line and what is wrong: a
// header other than collider_poses_header(), a row without 23 fields, a field that is not a
// finite number, an unknown shape, a frame number outside 1..2147483647, a scale or shape size
// that is not positive, a mesh collider whose collider_NAME.obj is missing or unusable.
std::map<int, std::vector<ColliderState>> read_collider_poses(const std::string& path);

}  // namespace grains
