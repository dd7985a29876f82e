// The collider planes on an OpenCL device (Iterations::find_planes; the kernels: grains.cl and
// kernels/planes.h). A work-item a grain counts its planes, a scan turns the counts into rows,
// and a second pass fills them; the rows, entries and colliders come back, or stay there and
// are compared there with those a contact list was built from.
#include <cstring>
#include <limits>
#include <map>
#include <stdexcept>
#include <vector>

#include "engine/buffer.h"
#include "engine/mesh_shape.h"
#include "nodes/grains/opencl/device_state.h"

namespace grains::opencl {

void Iterations::find_planes(const gr_collider* colliders, size_t count, const float origin[3],
                             float query_scale, const float* P, const float* p, const float* radius,
                             const float* inv_mass, size_t n, bool p_there, bool radius_there,
                             bool entries_stay, bool rows_stay, std::vector<uint32_t>* offsets,
                             std::vector<float>* plane, std::vector<int32_t>* which,
                             bool* same_as_kept) {
  Impl& m = *impl_;
  const size_t f = sizeof(float), u = sizeof(gr_uint);
  if (n >= size_t(std::numeric_limits<int>::max()) / 9 ||
      count >= size_t(std::numeric_limits<int>::max()))
    throw std::runtime_error("use_opencl: too many grains or colliders for the device's planes");
  offsets->resize(n + 1);
  m.open_neighbours();  // the scan
  cl_kernel kc = m.kernel(m.plane_count, "gr_k_plane_count");
  cl_kernel kf = m.kernel(m.plane_fill, "gr_k_plane_fill");
  // (once a substep: the final collision test there takes them too)
  m.upload_once(m.plane_colliders, colliders, count * sizeof(gr_collider));
  // the start positions, radii and inverse masses where the solve reads them (Impl::upload_once:
  // sent once a substep), the predicted positions where the search or the prediction left them,
  // and the radii the search's copies when it took these (its own must stay as it took them:
  // row_reach)
  // (within run()'s rebuild, the arrays the passes read stay as they are: where one holds
  // other values, such as the pre-stabilized start, the planes take their own; the start as it
  // went up where pre-stabilization there kept it)
  auto own = [&](Array k, Buffer& instead, const void* host, size_t bytes) -> Buffer& {
    return m.rebuilding && !m.holds(m.arrays[k], host, bytes) ? instead : m.arrays[k];
  };
  const bool kept = m.rebuilding && m.start_kept == n && !m.holds(m.arrays[kP], P, 3 * n * f);
  Buffer& Pb = kept ? m.start : own(kP, m.rebuild_P, P, 3 * n * f);
  if (!kept) m.upload_once(Pb, P, 3 * n * f, (3 * n + 1) * f);
  p_there = p_there && m.p_taken && m.p_taken_n == n;
  Buffer& pb = p_there ? *m.p_taken : m.plane_p;
  Buffer& rb = radius_there ? m.nb_radius : own(kRadius, m.rebuild_radius, radius, n * f);
  if (!p_there) m.upload(pb, p, 3 * n * f);
  if (!radius_there) {
    m.upload_once(rb, radius, n * f);
  } else {
    Buffer& to = m.arrays[kRadius];
    to.reserve(m.ctx, n * f, m.largest);
    check(clEnqueueCopyBuffer(m.queue, rb.mem, to.mem, 0, 0, n * f, 0, nullptr, nullptr),
          "clEnqueueCopyBuffer");
    m.copied_once(to, radius, n * f);
  }
  m.p_taken = &pb;
  m.p_taken_n = n;
  Buffer& wb = own(kInvMass, m.rebuild_inv_mass, inv_mass, n * f);
  m.upload_once(wb, inv_mass, n * f);
  Buffer& rows = m.arrays[kPlaneOffsets];
  rows.reserve(m.ctx, (n + 1) * u, m.largest);
  const int items = static_cast<int>(n), colliders_n = static_cast<int>(count);
  for (cl_kernel k : {kc, kf}) {
    arg(k, 0, m.plane_colliders), arg(k, 1, colliders_n);
    arg(k, 2, origin[0]), arg(k, 3, origin[1]), arg(k, 4, origin[2]), arg(k, 5, query_scale);
    arg(k, 6, Pb), arg(k, 7, pb), arg(k, 8, rb), arg(k, 9, wb);
    arg(k, 10, items), set_buffer(k, 11, m.meshes());
  }
  arg(kc, 12, rows);
  m.launch(kc, n);
  m.scan(rows, n);
  // with rows_stay only the last offset comes back: the number of entries
  if (rows_stay)
    m.download(rows, offsets->data() + n, u, n * u);
  else
    m.download(rows, offsets->data(), (n + 1) * u);
  const size_t entries = (*offsets)[n];
  m.plane_entries = entries;
  m.plane_grains = n;
  // the fall's wide ranges (|p - P|) can make many more rows than a resting pile keeps
  resize_for_rewrite(*plane, 9 * entries);
  resize_for_rewrite(*which, entries);
  const bool compare = rows_stay && m.kept_planes_n == n && m.kept_plane_entries == entries;
  if (same_as_kept) *same_as_kept = compare && entries == 0;  // no rows: every one empty
  if (entries == 0) return;
  m.arrays[kPlane].reserve(m.ctx, 9 * entries * f, m.largest);
  m.plane_collider.reserve(m.ctx, entries * sizeof(int), m.largest);
  arg(kf, 12, rows), arg(kf, 13, m.arrays[kPlane]), arg(kf, 14, m.plane_collider);
  m.launch(kf, n);
  if (!entries_stay) m.download(m.arrays[kPlane], plane->data(), 9 * entries * f);
  if (!rows_stay) m.download(m.plane_collider, which->data(), entries * sizeof(int));
  if (!compare || !same_as_kept) return;
  // offsets, which, kept_offsets, kept_which, n, differs
  cl_kernel k = m.kernel(m.plane_same, "gr_k_plane_same");
  m.plane_differs.reserve(m.ctx, sizeof(int), m.largest);
  int differs = 0;
  check(clEnqueueFillBuffer(m.queue, m.plane_differs.mem, &differs, sizeof differs, 0,
                            sizeof differs, 0, nullptr, nullptr),
        "clEnqueueFillBuffer");
  arg(k, 0, rows), arg(k, 1, m.plane_collider), arg(k, 2, m.kept_plane_offsets);
  arg(k, 3, m.kept_plane_which), arg(k, 4, items), arg(k, 5, m.plane_differs);
  m.launch(k, n);
  m.download(m.plane_differs, &differs, sizeof differs);
  *same_as_kept = differs == 0;
}

void Iterations::set_meshes(const std::vector<std::shared_ptr<const MeshShape>>& meshes) {
  Impl& m = *impl_;
  if (meshes == m.mesh_key) return;
  m.mesh_key = meshes;
  m.any_meshes = false;
  for (const auto& mesh : meshes) m.any_meshes = m.any_meshes || mesh != nullptr;
  if (!m.any_meshes) return;
  // a record a collider, then each mesh's arrays once (colliders may share one), as
  // engine/mesh_query.h's gr_mesh_of reads them
  static_assert(sizeof(gr_mesh_ref) == 13 * sizeof(int32_t) && sizeof(gr_mesh_node) == 32,
                "the words as the device reads them");
  const size_t record = sizeof(gr_mesh_ref) / sizeof(int32_t);
  // (kept: the upload reads them after this returns)
  std::vector<int32_t>& words = m.mesh_host;
  words.assign(record * meshes.size(), 0);
  auto add = [&](const void* data, size_t bytes) {
    const size_t at = words.size();
    if (at + bytes / 4 >= size_t(std::numeric_limits<int>::max()))
      throw std::runtime_error("use_opencl: the collider meshes are too large for the device");
    words.resize(at + bytes / 4);
    if (bytes > 0) std::memcpy(words.data() + at, data, bytes);
    return static_cast<int>(at);
  };
  std::map<const MeshShape*, gr_mesh_ref> placed;
  for (size_t c = 0; c < meshes.size(); ++c) {
    gr_mesh_ref ref{};
    ref.nodes = -1;
    const MeshShape* shape = meshes[c].get();
    if (shape && placed.count(shape)) {
      ref = placed[shape];
    } else if (shape) {
      const gr_mesh v = shape->view();
      const size_t nt = shape->triangle_count(), nv = shape->mesh().vertices.size();
      const size_t f = sizeof(float);
      ref.nodes = add(v.nodes, shape->node_count() * sizeof(gr_mesh_node));
      ref.tri = add(v.tri, 3 * nt * sizeof(int));
      ref.vertices = add(v.vertices, 3 * nv * f);
      ref.face_n = add(v.face_n, 3 * nt * f);
      ref.edge_n = add(v.edge_n, 9 * nt * f);
      ref.vertex_n = add(v.vertex_n, 3 * nv * f);
      ref.closed = v.closed;
      for (int k = 0; k < 3; ++k) ref.lo[k] = v.lo[k], ref.hi[k] = v.hi[k];
      placed[shape] = ref;
    }
    std::memcpy(words.data() + record * c, &ref, sizeof ref);
  }
  m.upload(m.mesh_words, words.data(), words.size() * sizeof(int32_t));
}

void Iterations::fetch_planes(std::vector<float>* plane, std::vector<uint32_t>* offsets,
                              std::vector<int32_t>* which) {
  Impl& m = *impl_;
  const size_t n = m.plane_grains, entries = m.plane_entries;
  if (plane) {
    resize_for_rewrite(*plane, 9 * entries);
    m.download(m.arrays[kPlane], plane->data(), 9 * entries * sizeof(float));
  }
  if (offsets) {
    offsets->resize(n + 1);
    m.download(m.arrays[kPlaneOffsets], offsets->data(), (n + 1) * sizeof(gr_uint));
  }
  if (which && entries > 0) {
    which->resize(entries);
    m.download(m.plane_collider, which->data(), entries * sizeof(int));
  }
}

void Iterations::Impl::copy_plane_rows(Buffer& offsets, Buffer& which) {
  const size_t n = plane_grains, entries = plane_entries, u = sizeof(gr_uint);
  offsets.reserve(ctx, (n + 1) * u, largest);
  check(clEnqueueCopyBuffer(queue, arrays[kPlaneOffsets].mem, offsets.mem, 0, 0, (n + 1) * u, 0,
                            nullptr, nullptr),
        "clEnqueueCopyBuffer");
  which.reserve(ctx, entries * sizeof(int), largest);
  if (entries > 0)
    check(clEnqueueCopyBuffer(queue, plane_collider.mem, which.mem, 0, 0, entries * sizeof(int), 0,
                              nullptr, nullptr),
          "clEnqueueCopyBuffer");
}

void Iterations::hold_planes() {
  Impl& m = *impl_;
  m.copy_plane_rows(m.held_plane_offsets, m.held_plane_which);
  m.held_planes_n = m.plane_grains;
}

void Iterations::carry_planes(size_t n, bool sums, bool slips, bool slots) {
  Impl& m = *impl_;
  if (m.held_planes_n != n || m.plane_grains != n)
    throw std::logic_error("carry_planes: the device holds no such planes");
  const size_t f = sizeof(float), entries = m.plane_entries;
  cl_kernel k = m.kernel(m.carry_planes, "gr_k_carry_planes");
  if (sums) m.carried_sum.reserve(m.ctx, entries * f, m.largest);
  if (slips) m.carried_slip.reserve(m.ctx, 3 * entries * f, m.largest);
  m.plane_collider.reserve(m.ctx, entries * sizeof(int), m.largest);  // bound even when empty
  // old rows, colliders, sums and slips; the new ones; the slots; n
  arg(k, 0, m.held_plane_offsets), arg(k, 1, m.held_plane_which);
  set_buffer(k, 2, sums ? &m.collider_sum : nullptr);
  set_buffer(k, 3, slips ? &m.arrays[kPlaneSlip] : nullptr);
  arg(k, 4, m.arrays[kPlaneOffsets]), arg(k, 5, m.plane_collider);
  set_buffer(k, 6, sums ? &m.carried_sum : nullptr);
  set_buffer(k, 7, slips ? &m.carried_slip : nullptr);
  set_buffer(k, 8, slots ? &m.collider_dx : nullptr);
  arg(k, 9, static_cast<int>(n));
  m.launch(k, n);
  if (sums) {
    m.forget(m.collider_sum);
    std::swap(m.collider_sum, m.carried_sum);
  }
  if (slips) {
    m.forget(m.arrays[kPlaneSlip]);
    std::swap(m.arrays[kPlaneSlip], m.carried_slip);
  }
  m.held_planes_n = 0;
}

void Iterations::keep_planes() {
  Impl& m = *impl_;
  m.copy_plane_rows(m.kept_plane_offsets, m.kept_plane_which);
  m.kept_planes_n = m.plane_grains;
  m.kept_plane_entries = m.plane_entries;
}

}  // namespace grains::opencl
