#include "nodes/common.h"

#include <cmath>
#include <filesystem>

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

}  // namespace grains
