// VTK XML frames (docs/output-format.md): what ParaView, VisIt and VTK's own readers open with
// every attribute, beside the PLY frames of DESIGN §6 (`output.formats` ["ply", "vtp"]).
#pragma once
#include <string>
#include <vector>

#include "engine/particles.h"

namespace grains {

// Writes one frame as a VTK XML PolyData file (.vtp, raw appended binary in the host's byte
// order, 64-bit headers and cell indices):
//   Points: P (Float32 x 3);
//   Verts: one vertex cell per point, so the grains show without a filter;
//   Lines: one line cell per primitive (the explicit constraints), its two points;
//   PointData: the PLY's vertex columns as arrays named like the store's attributes: v (x 3),
//     pscale, id (Int32), then each of `attributes` (Float → Float32, Int → Int32, Vec3 →
//     Float32 x 3; one the store lacks with its documented default), or with `all` every
//     attribute the store holds; pscale is the active scalars and v the active vectors;
//   CellData: restlength and strain (with `all` every primitive attribute), one value per cell:
//     NaN on the vertex cells, which are not constraints, then one per line cell;
//   FieldData: TimeValue, the frame's time (s).
// Written to PATH.tmp then renamed, like the PLY frames. Throws WriteError when the system
// refuses a write.
void write_vtp(const std::string& path, const ParticleStore& pts,
               const std::vector<std::string>& attributes, bool all, double time);

// One frame of a collection: its time (s) and its file, relative to the collection's folder.
struct VtkDataSet {
  double time = 0;
  std::string file;
};

// Writes a VTK collection (.pvd) listing `frames` in order, each with its time, the one file
// ParaView opens to animate a run. Written to PATH.tmp then renamed: a run rewrites it after each
// frame, so a killed run leaves one that lists the frames it wrote. Throws WriteError.
void write_pvd(const std::string& path, const std::vector<VtkDataSet>& frames);

// Reads a collection this program wrote (one DataSet element a line); an absent or foreign file
// gives no frames.
std::vector<VtkDataSet> read_pvd(const std::string& path);

}  // namespace grains
