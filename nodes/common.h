// Small helpers shared by node implementations.
#pragma once
#include <cstdint>
#include <memory>
#include <string>

#include "engine/vec3.h"

namespace grains {

// Deterministic random numbers: a 64-bit mix of (seed, counter), uniform in [0, 1).
inline uint64_t mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}
inline float rand01(uint64_t seed, uint64_t counter) {
  return static_cast<float>(mix64(seed ^ mix64(counter)) >> 40) / static_cast<float>(1ULL << 24);
}

// Resolves a path relative to the graph's folder.
std::string resolve_path(const std::string& base_dir, const std::string& path);

// The shape of mesh file `path` (OBJ or PLY triangles, engine/mesh_shape.h), read and built once
// per process for each version of the file (its size and modification time): colliders are
// posed every substep and a hierarchy costs far more than a pose. Throws GeometryError
// ("PATH: what is wrong") for a missing or unusable file.
class MeshShape;
std::shared_ptr<const MeshShape> cached_mesh_shape(const std::string& path);

// Region test shared by group and kill: a box (center, full size), a sphere (center, radius) or
// a cylinder (vertical: axis along y through center, radius, height size.y; kill only). In the
// order of kill's `shape` menu.
enum class Region { Box, Sphere, Cylinder };
bool inside_region(Region shape, const Vec3& center, const Vec3& size, float radius, const Vec3& p);

}  // namespace grains
