// A triangle mesh as a collider shape: the exact distance to its surface through a
// bounding-volume hierarchy of its triangles.
//
// Closed meshes (every edge shared by exactly two triangles that run along it in opposite
// directions, after welding vertices at equal positions) are solids: the distance is signed,
// negative inside, the side told by the angle-weighted pseudonormal of the nearest feature
// (face, edge or vertex; Baerentzen & Aanaes 2005), which is exact wherever the nearest point is
// unique. A closed mesh wound inward is turned outward (its signed volume decides). Any other
// mesh is a shell (a sheet, a bowl's wall): the distance is unsigned, so a grain is kept at its
// radius from either side, and the final collision pass's sweep stops it crossing.
//
// The query walks the hierarchy nearest box first and skips every box farther than the best
// triangle found; triangle tests are in double precision so that the nearest feature, and with
// it the sign, does not flip between the two triangles of an edge. The queries are
// engine/mesh_query.h's, which an OpenCL device runs on the same arrays (view()).
#pragma once
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "engine/geometry_io.h"
#include "engine/mesh_query.h"
#include "engine/vec3.h"

namespace grains {

class MeshShape {
 public:
  // Builds the shape of `mesh` (local coordinates). Returns null and sets *problem when the mesh
  // has no triangle of non-zero area or a vertex index out of range.
  static std::shared_ptr<const MeshShape> build(const Mesh& mesh, std::string* problem);

  // Distance from local point p to the surface (signed for a closed mesh, negative inside;
  // unsigned for a shell) and the unit normal along which it grows (outward for a closed mesh).
  // Exact when it is below `within`; a point at least `within` from the surface (outside) gets
  // some value between `within` and its distance, and an arbitrary normal: the walk then skips
  // every box farther than `within`, which is what makes a query from inside a bowl cheap.
  float distance(const Vec3& p, Vec3* normal,
                 float within = std::numeric_limits<float>::infinity()) const;

  // The first point where the segment a -> b (local) passes through a triangle: returns its
  // fraction along the segment in (0, 1] and the triangle's unit normal, or a value > 1 when
  // the segment touches no triangle after its start (a start on the surface is on no side). A shell has no inside, so this is how a grain that went
  // through one is told from one that stayed on its side.
  float crossing(const Vec3& a, const Vec3& b, Vec3* normal) const;

  bool closed() const { return closed_; }
  size_t triangle_count() const { return tri_.size(); }
  Vec3 lower() const { return lo_; }  // bounding box of the vertices
  Vec3 upper() const { return hi_; }
  float bound_radius() const { return bound_radius_; }  // largest |vertex|
  // The welded mesh the shape measures (triangles of zero area dropped; inward closed meshes
  // turned outward), e.g. to write it beside a run's output.
  const Mesh& mesh() const { return mesh_; }
  // The shape's arrays in the shared queries' form (engine/mesh_query.h), pointing into this
  // shape: valid while it lives (made once by build(); a shape is not copied). A device's copy
  // takes node_count() nodes, triangle_count() triangles and mesh().vertices.size() vertices
  // from it.
  const gr_mesh& view() const { return view_; }
  size_t node_count() const { return nodes_.size(); }

 private:
  using Node = gr_mesh_node;
  Mesh mesh_;
  std::vector<std::array<int, 3>> tri_;  // in hierarchy order
  std::vector<Vec3> face_n_;             // unit normal per triangle (hierarchy order)
  std::vector<Vec3> edge_n_;             // 3 per triangle: edge (v0 v1), (v1 v2), (v2 v0)
  std::vector<Vec3> vertex_n_;           // angle-weighted pseudonormal per vertex
  std::vector<Node> nodes_;
  Vec3 lo_, hi_;
  float bound_radius_ = 0;
  bool closed_ = false;
  gr_mesh view_{};    // the arrays above, for the queries (view())
  void point_view();  // view_ at them, once they are built

 public:
  MeshShape() = default;
  MeshShape(const MeshShape&) = delete;  // view_ points into this shape's own arrays
  MeshShape& operator=(const MeshShape&) = delete;
};

}  // namespace grains
