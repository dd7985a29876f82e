// Geometry files: PLY frames (DESIGN §6) and PLY/OBJ inputs for sources, targets and colliders.
#pragma once
#include <array>
#include <cstdio>
#include <functional>
#include <stdexcept>
#include <cstdint>
#include <string>
#include <vector>

#include "engine/particles.h"

namespace grains {

// Bad or unreadable geometry file; what() names the file and what is wrong.
struct GeometryError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A file could not be written (disk full, quota, I/O error, ...); what() names the file and gives
// the system's reason. A failure of the run (exit 1), not bad input.
struct WriteError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Writes a file to PATH.tmp with `write` (which returns false when an fwrite falls short), then
// renames it to PATH, so a killed run never leaves a half-written file under PATH. On failure
// removes PATH.tmp and throws WriteError: "PATH: cannot write (reason)" or "PATH: cannot rename
// PATH.tmp (reason)". Shared by the PLY and VTK frame writers.
void write_file_atomically(const std::string& path, const std::function<bool(std::FILE*)>& write);

// Writes one frame as binary little-endian PLY, DESIGN §6:
//   element vertex: float x y z, float vx vy vz, float pscale, int id, then each requested attribute
//     (Float → float NAME, Int → int NAME, Vec3 → float NAME_x NAME_y NAME_z); a requested attribute
//     that the store lacks is written with its documented default;
//   element edge: int vertex1 vertex2, float restlength strain (one per primitive).
// Written to PATH.tmp then renamed, so a killed run never leaves a half-written frame. Throws
// WriteError when the system refuses a write.
void write_ply(const std::string& path, const ParticleStore& pts,
               const std::vector<std::string>& attributes);
// Same, with every attribute the store holds (used by `grains cook`).
void write_ply_all(const std::string& path, const ParticleStore& pts);

// Reads a PLY file (ascii, binary_little_endian or binary_big_endian) into a particle store.
// Vertex properties: x y z → P; vx vy vz → v; NAME_x NAME_y NAME_z → Vec3 NAME; other float or
// double properties → Float; integer properties → Int (id included; ids are assigned when absent
// and next_id is set past the largest). Edge element (vertex1 vertex2, plus float properties →
// primitive attributes) → primitives; a missing restlength is the distance at load.
// Inputs are plain files of bounded size: a folder, a device (/dev/zero) or a file past the
// limit is refused before any byte is read. Returns what is wrong ("" when nothing).
constexpr uint64_t kMaxGeometryFileBytes = uint64_t(8) << 30;  // 8 GiB: about 300 M points
constexpr uint64_t kMaxGraphFileBytes = uint64_t(64) << 20;    // 64 MiB of JSON
std::string input_file_problem(const std::string& path, uint64_t max_bytes);

// Throws GeometryError (file + what) for a missing file, bad header, no x/y/z, a known attribute
// of the wrong type (e.g. an int pscale), edge indices out of range, truncated data.
// The store also holds the standard attributes at their defaults (pscale 0.05, mass 1, ...);
// `from_file`, when given, receives the names of the point attributes the file itself provides
// (P, v, pscale, ... in the order of its properties), so a caller can tell the two apart.
ParticleStore read_ply(const std::string& path, std::vector<std::string>* from_file = nullptr);

struct Mesh {
  std::vector<Vec3> vertices;
  std::vector<std::array<int, 3>> triangles;  // polygons are fan-triangulated
};
// Reads a Wavefront OBJ (v and f lines; f may use v/vt/vn and negative indices).
Mesh read_obj(const std::string& path);
// Reads points from .ply (vertex positions) or .obj (vertices) by extension.
Mesh read_mesh(const std::string& path);
// Writes a mesh as a Wavefront OBJ (v lines with 9 significant digits, which read back to the
// same floats; f lines of 1-based indices), atomically as write_file_atomically.
void write_obj(const std::string& path, const Mesh& mesh);

}  // namespace grains
