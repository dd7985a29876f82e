#include "nodes/common.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>

#include "engine/geometry_io.h"
#include "engine/mesh_shape.h"

namespace grains {

std::string resolve_path(const std::string& base_dir, const std::string& path) {
  std::filesystem::path p(path);
  if (p.is_absolute() || base_dir.empty()) return path;
  return (std::filesystem::path(base_dir) / p).string();
}

bool inside_region(Region shape, const Vec3& c, const Vec3& size, float radius, const Vec3& p) {
  Vec3 d = p - c;
  if (shape == Region::Sphere) return dot(d, d) <= radius * radius;
  if (shape == Region::Cylinder)
    return d.x * d.x + d.z * d.z <= radius * radius && std::fabs(d.y) <= size.y * 0.5f;
  return std::fabs(d.x) <= size.x * 0.5f && std::fabs(d.y) <= size.y * 0.5f &&
         std::fabs(d.z) <= size.z * 0.5f;
}

std::shared_ptr<const MeshShape> cached_mesh_shape(const std::string& path) {
  static std::mutex mutex;
  static std::map<std::string, std::pair<std::string, std::shared_ptr<const MeshShape>>> cache;
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  const auto time = std::filesystem::last_write_time(path, ec);
  const std::string version =
      std::to_string(size) + "@" + std::to_string(time.time_since_epoch().count());
  std::lock_guard<std::mutex> lock(mutex);
  auto& entry = cache[path];
  if (entry.second && entry.first == version) return entry.second;
  std::string problem;
  std::shared_ptr<const MeshShape> shape = MeshShape::build(read_mesh(path), &problem);
  if (!shape) throw GeometryError(path + ": " + problem);
  entry = {version, shape};
  return shape;
}

}  // namespace grains
