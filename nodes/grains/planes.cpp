// The collider planes of the substep (kernels/planes.h): on the CPU here, or on the OpenCL
// device (opencl/planes.cpp), which finds the same floats. This file, like engine/collider.cpp,
// is compiled without contraction of multiplies and adds (CMakeLists.txt), as the device runs
// the shared functions (GR_SHAPE_EXACT).
#include "nodes/grains/kernels/planes.h"

#include <algorithm>
#include <vector>

#include "engine/buffer.h"
#include "nodes/grains/opencl/iterations.h"
#include "nodes/grains/solver.h"

namespace grains {

void GrainsSolver::find_planes(const float* P, const float* p, const Vec3& origin,
                               const ColliderState* colliders, size_t collider_count,
                               float query_scale, int threads, const DevicePlanes* device) {
  const size_t n = n_;
  const long ln = static_cast<long>(n);
  const float* radius = radius_;
  const float o[3] = {origin.x, origin.y, origin.z};
  // the colliders in the shared functions' form (a mesh keeps its kind and poses there)
  std::vector<gr_collider>& shapes = plane_colliders_;
  shapes.resize(collider_count);
  for (size_t c = 0; c < collider_count; ++c) shapes[c] = to_gr(colliders[c]);
  // use_opencl: the planes are found on the device, with the colliders' meshes there
  // (meshes_here decides)
  if (device) {
    std::vector<std::shared_ptr<const MeshShape>>& meshes = device_meshes_;
    meshes.resize(collider_count);
    for (size_t c = 0; c < collider_count; ++c) meshes[c] = colliders[c].shape.mesh;
    open_device().set_meshes(meshes);
    const bool stay = device->entries_stay;
    const bool rows_stay = stay && device->rows_stay;
    open_device().find_planes(shapes.data(), collider_count, o, query_scale, P, p, radius,
                              inv_mass_.data(), n, device->p_there, device->radius_there, stay,
                              rows_stay, &plane_offsets_, &plane_, &plane_collider_, &planes_same_);
    ++planes_device_;
    planes_on_device_ = true;
    device_.planes_stale = stay;
    plane_rows_there_ = device_.plane_rows_stale = rows_stay;
    return;
  }
  planes_on_device_ = device_.planes_stale = false;
  plane_rows_there_ = device_.plane_rows_stale = false;
  // Two passes: count (row sizes), then fill the compact rows; each grain writes only its own
  // row
  std::vector<const void*> meshes(collider_count);
  for (size_t c = 0; c < collider_count; ++c) meshes[c] = colliders[c].shape.mesh.get();
  const int count = static_cast<int>(collider_count);
  auto nearest = [&](long i, float* dist, float* nrm, int32_t* idx) {
    return gr_plane_nearest(shapes.data(), count, o, query_scale, radius[i], inv_mass_[i],
                            p + 3 * i, P + 3 * i, dist, nrm, idx, meshes.data());
  };
  plane_offsets_.resize(n + 1);
  uint32_t* offsets = plane_offsets_.data();
  offsets[0] = 0;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long i = 0; i < ln; ++i) {
    float dist[GR_MAX_PLANES], nrm[3 * GR_MAX_PLANES];
    int32_t idx[GR_MAX_PLANES];
    offsets[i + 1] = static_cast<uint32_t>(nearest(i, dist, nrm, idx));
  }
  for (size_t i = 0; i < n; ++i) offsets[i + 1] += offsets[i];
  // the fall's wide ranges (|p - P| above) can make many more rows than a resting pile keeps
  resize_for_rewrite(plane_, 9 * size_t(offsets[n]));
  resize_for_rewrite(plane_collider_, offsets[n]);
  float* plane = plane_.data();
  int32_t* which = plane_collider_.data();
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long i = 0; i < ln; ++i) {
    if (offsets[i + 1] == offsets[i]) continue;
    float dist[GR_MAX_PLANES], nrm[3 * GR_MAX_PLANES];
    int32_t idx[GR_MAX_PLANES];
    const int count = nearest(i, dist, nrm, idx);
    for (int k = 0; k < count; ++k) {
      const uint32_t e = offsets[i] + k;
      float* entry = plane + 9 * size_t(e);
      float world[3];
      gr_plane_surface(p + 3 * i, nrm + 3 * k, dist[k], o, entry, world);
      std::copy(nrm + 3 * k, nrm + 3 * k + 3, entry + 3);
      gr_collider_velocity(&shapes[idx[k]], world, entry + 6);
      which[e] = idx[k];
    }
  }
}

bool GrainsSolver::any_mesh(const ColliderState* colliders, size_t count) {
  for (size_t c = 0; c < count; ++c)
    if (colliders[c].shape.kind == ShapeKind::Mesh) return true;
  return false;
}

bool GrainsSolver::meshes_here(const GrainsSettings& s, const ColliderState* colliders,
                               size_t count) {
  return any_mesh(colliders, count) &&
         !(s.use_opencl && !s.host_mesh && open_device().meshes_there());
}

}  // namespace grains
