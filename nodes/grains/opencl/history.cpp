// The Jacobi path's contact history between grains on the device (kernels/history.h, grains.cl's
// gr_k_save_pair_slips, gr_k_history_table and gr_k_load_pair_slips): the slips saved at a
// substep's end stay here with the rows they belong to, and the next substep's carried slips are
// made here from them, so that neither crosses (12 bytes a row entry each way).
#include <cstdint>
#include <utility>
#include <vector>

#include "nodes/grains/opencl/device_state.h"
#include "nodes/grains/opencl/iterations.h"

namespace grains::opencl {

bool Iterations::save_pair_history(const gr_grains& g, const gr_params& prm,
                                   const IterationSizes& size, const float* p,
                                   const gr_uint* pair_normal, bool p_there) {
  Impl& m = *impl_;
  const size_t n = size.n, entries = size.pair_entries, f = sizeof(float), u = sizeof(gr_uint);
  m.hist_saved = false;
  if (n == 0 || !g.nbr_offsets || !g.pair_slip || !size.rows_there || !m.rows_found ||
      m.rows_grains != n)
    return false;
  // what the kernel reads: the start, radii and friction (held from the substep's calls), the
  // rows (copied from the search's), the carried slips (made or sent), the pair sums (as the
  // last call gave them back) and the positions, where the last run() left them (p_there) or
  // sent
  HostArray a[kArrays];
  grain_arrays(g, size, a);
  m.stand_in_rows(size, a);  // the rows' indices without a host copy
  m.upload_once(m.arrays[kP], a[kP].host, a[kP].bytes, a[kP].bytes + f);
  m.upload_once(m.arrays[kRadius], a[kRadius].host, a[kRadius].bytes);
  m.upload_once(m.arrays[kFriction], a[kFriction].host, a[kFriction].bytes);
  m.copy_once(m.arrays[kNbrOffsets], m.nb_offsets, a[kNbrOffsets].host, a[kNbrOffsets].bytes);
  m.copy_once(m.arrays[kNbrIndices], m.nb_indices, a[kNbrIndices].host, a[kNbrIndices].bytes);
  if (!size.slips_there) m.upload(m.arrays[kPairSlip], a[kPairSlip].host, a[kPairSlip].bytes);
  if (!m.holds(m.pair_sum, pair_normal, entries * u)) {
    m.hist_sums_host.assign(pair_normal, pair_normal + entries);
    m.upload(m.pair_sum, m.hist_sums_host.data(), entries * u);
  }
  const Buffer* positions = &m.p;
  if (p_there && m.run_out_n == n) {
    positions = m.run_out;
  } else {
    m.hist_p_host.assign(p, p + 3 * n);
    m.upload(m.p, m.hist_p_host.data(), 3 * n * f);
    m.run_out = &m.p, m.run_out_n = n;  // the iterations' end, for the planes' save
  }
  m.hist_slip.reserve(m.ctx, 3 * entries * f, m.largest);
  HostArray bound[kArrays] = {};
  for (int k : {kP, kRadius, kFriction, kNbrOffsets, kNbrIndices, kPairSlip}) bound[k] = a[k];
  cl_kernel k = m.kernel(m.save_pair_slips, "gr_k_save_pair_slips");
  const int count = static_cast<int>(n);
  m.set_grains(k, prm, g, bound);
  set_buffer(k, kFirstOwn, positions);
  set_buffer(k, kFirstOwn + 1, &m.pair_sum);
  set_buffer(k, kFirstOwn + 2, &m.hist_slip);
  check(clSetKernelArg(k, kFirstOwn + 3, sizeof(int), &count), "clSetKernelArg");
  m.launch(k, n);
  // the rows they belong to, which the next search replaces
  m.hist_offsets.reserve(m.ctx, (n + 1) * u, m.largest);
  m.hist_indices.reserve(m.ctx, entries * u, m.largest);
  check(clEnqueueCopyBuffer(m.queue, m.arrays[kNbrOffsets].mem, m.hist_offsets.mem, 0, 0,
                            (n + 1) * u, 0, nullptr, nullptr),
        "clEnqueueCopyBuffer");
  if (entries > 0)
    check(clEnqueueCopyBuffer(m.queue, m.arrays[kNbrIndices].mem, m.hist_indices.mem, 0, 0,
                              entries * u, 0, nullptr, nullptr),
          "clEnqueueCopyBuffer");
  m.hist_entries = entries;
  m.hist_grains = n;
  m.hist_saved = true;
  return true;
}

bool Iterations::save_plane_history(const gr_grains& g, const gr_params& prm,
                                    const IterationSizes& size, const float* collider_normal,
                                    float* out) {
  Impl& m = *impl_;
  const size_t n = size.n, entries = size.plane_entries, f = sizeof(float);
  if (n == 0 || !g.plane_offsets || !m.run_out || m.run_out_n != n) return false;
  // kept: the planes' rows must be those the last find_planes() left there
  if (!out && (!size.planes_there || m.plane_grains != n || m.plane_entries != entries))
    return false;
  if (entries == 0 && out) return true;  // (nothing to save: the planes' slips may be unset)
  if (!g.plane_slip && entries > 0) return false;
  // the grains' arrays and the planes as run() bound them (no call has sent others since:
  // run_out_n), the sums as it brought them back
  HostArray a[kArrays];
  grain_arrays(g, size, a);
  HostArray bound[kArrays] = {};
  for (int k : {kP, kRadius, kFriction, kPlaneOffsets, kPlane, kPlaneSlip}) bound[k] = a[k];
  if (entries > 0) {
    m.upload_once(m.collider_sum, collider_normal, entries * f);
    m.plane_saved.reserve(m.ctx, 3 * entries * f, m.largest);
    cl_kernel k = m.kernel(m.save_plane_slips, "gr_k_save_plane_slips");
    const int count = static_cast<int>(n);
    m.set_grains(k, prm, g, bound);
    set_buffer(k, kFirstOwn, m.run_out);
    set_buffer(k, kFirstOwn + 1, &m.collider_sum);
    set_buffer(k, kFirstOwn + 2, &m.plane_saved);
    check(clSetKernelArg(k, kFirstOwn + 3, sizeof(int), &count), "clSetKernelArg");
    m.launch(k, n);
  }
  if (out) {
    m.download(m.plane_saved, out, 3 * entries * f);
    return true;
  }
  // kept here with the rows, colliders and sums they belong to, which the next find_planes()
  // and run() replace
  const size_t u = sizeof(gr_uint);
  m.hist_plane_offsets.reserve(m.ctx, (n + 1) * u, m.largest);
  m.hist_plane_which.reserve(m.ctx, entries * sizeof(int), m.largest);
  m.hist_plane_sum.reserve(m.ctx, entries * f, m.largest);
  const std::pair<const Buffer*, Buffer*> copies[] = {
      {&m.arrays[kPlaneOffsets], &m.hist_plane_offsets},
      {&m.plane_collider, &m.hist_plane_which},
      {&m.collider_sum, &m.hist_plane_sum}};
  const size_t bytes[] = {(n + 1) * u, entries * sizeof(int), entries * f};
  for (int c = 0; c < (entries > 0 ? 3 : 1); ++c)
    check(clEnqueueCopyBuffer(m.queue, copies[c].first->mem, copies[c].second->mem, 0, 0, bytes[c],
                              0, nullptr, nullptr),
          "clEnqueueCopyBuffer");
  m.hist_plane_entries = entries;
  m.hist_plane_grains = n;
  m.hist_planes_saved = true;
  return true;
}

bool Iterations::load_plane_history(const IterationSizes& size, bool same, const int* id,
                                    const int* hist_id, size_t hist_n, size_t table_size) {
  Impl& m = *impl_;
  const size_t n = size.n, entries = size.plane_entries, f = sizeof(float);
  if (!m.hist_planes_saved || n == 0 || !size.planes_there || m.plane_grains != n ||
      m.plane_entries != entries || (same && m.hist_plane_grains != n))
    return false;
  Buffer& slip = m.arrays[kPlaneSlip];
  slip.reserve(m.ctx, 3 * entries * f, m.largest);
  m.forget(slip);
  if (entries == 0) return true;
  // offsets, which, id, table, table_size, hist_offsets, hist_which, hist_normal, hist_slip,
  // slip, n
  cl_kernel k = m.kernel(m.load_plane_slips, "gr_k_load_plane_slips");
  if (!m.lookup_by_id(k, slip, 3 * entries, same, m.hist_plane_grains == hist_n, n, id, hist_id,
                      hist_n, table_size))
    return true;
  const int count = static_cast<int>(n);
  set_buffer(k, 0, &m.arrays[kPlaneOffsets]);
  set_buffer(k, 1, &m.plane_collider);
  set_buffer(k, 5, &m.hist_plane_offsets);
  set_buffer(k, 6, &m.hist_plane_which);
  set_buffer(k, 7, &m.hist_plane_sum);
  set_buffer(k, 8, &m.plane_saved);
  set_buffer(k, 9, &slip);
  check(clSetKernelArg(k, 10, sizeof(int), &count), "clSetKernelArg");
  m.launch(k, n);
  return true;
}

void Iterations::fetch_plane_history(std::vector<uint32_t>* offsets, std::vector<int32_t>* which,
                                     std::vector<float>* normal, std::vector<float>* slip) {
  Impl& m = *impl_;
  const size_t n = m.hist_plane_grains, entries = m.hist_plane_entries;
  offsets->resize(n + 1);
  which->resize(entries);
  normal->resize(entries);
  slip->resize(3 * entries);
  m.download(m.hist_plane_offsets, offsets->data(), (n + 1) * sizeof(gr_uint));
  m.download(m.hist_plane_which, which->data(), entries * sizeof(int));
  m.download(m.hist_plane_sum, normal->data(), entries * sizeof(float));
  m.download(m.plane_saved, slip->data(), 3 * entries * sizeof(float));
}

void Iterations::fetch_plane_slips(float* out, float* collider_normal, size_t entries) {
  Impl& m = *impl_;
  m.download(m.arrays[kPlaneSlip], out, 3 * entries * sizeof(float));
  m.download(m.collider_sum, collider_normal, entries * sizeof(float));
}

bool Iterations::Impl::lookup_by_id(cl_kernel k, Buffer& slip, size_t floats, bool same,
                                    bool usable, size_t n, const int* id, const int* hist_id,
                                    size_t hist_n, size_t table_size) {
  if (!same && (!usable || !hist_id || hist_n == 0 || table_size == 0)) {
    const float zero = 0.0f;
    check(clEnqueueFillBuffer(queue, slip.mem, &zero, sizeof zero, 0, floats * sizeof zero, 0,
                              nullptr, nullptr),
          "clEnqueueFillBuffer");
    return false;
  }
  if (!same) history_table(n, id, hist_id, hist_n, table_size);
  const int table = same ? 0 : static_cast<int>(table_size);
  set_buffer(k, 2, !same && id ? &this->id : nullptr);
  set_buffer(k, 3, same ? nullptr : &hist_table);
  check(clSetKernelArg(k, 4, sizeof(int), &table), "clSetKernelArg");
  return true;
}

void Iterations::Impl::history_table(size_t n, const int* id, const int* hist_id, size_t hist_n,
                                     size_t table_size) {
  if (table_made) return;  // this substep's, for the pairs' lookup
  const size_t i = sizeof(int);
  upload_once(this->id, id, n * i);
  hist_id_host.assign(hist_id, hist_id + hist_n);
  upload(this->hist_id, hist_id_host.data(), hist_n * i);
  hist_table.reserve(ctx, table_size * i, largest);
  const int none = -1, olds = static_cast<int>(hist_n);
  check(
      clEnqueueFillBuffer(queue, hist_table.mem, &none, i, 0, table_size * i, 0, nullptr, nullptr),
      "clEnqueueFillBuffer");
  cl_kernel t = kernel(history_table_kernel, "gr_k_history_table");
  set_buffer(t, 0, &this->hist_id);
  check(clSetKernelArg(t, 1, sizeof(int), &olds), "clSetKernelArg");
  set_buffer(t, 2, &hist_table);
  launch(t, hist_n);
  table_made = true;
}

bool Iterations::load_pair_history(const IterationSizes& size, bool kept, bool same, const int* id,
                                   const int* hist_id, size_t hist_n, size_t table_size) {
  Impl& m = *impl_;
  const size_t n = size.n, entries = size.pair_entries, f = sizeof(float);
  if (!m.hist_saved || n == 0) return false;
  Buffer& slip = m.arrays[kPairSlip];
  if (kept) {
    // the same rows: each entry's slip is where it was saved
    if (entries != m.hist_entries || n != m.hist_grains) return false;
    slip.reserve(m.ctx, 3 * entries * f, m.largest);
    if (entries > 0)
      check(clEnqueueCopyBuffer(m.queue, m.hist_slip.mem, slip.mem, 0, 0, 3 * entries * f, 0,
                                nullptr, nullptr),
            "clEnqueueCopyBuffer");
    m.forget(slip);
    return true;
  }
  // new rows, where the search left them
  if (!size.rows_there || !m.rows_found || m.rows_grains != n || (same && m.hist_grains != n))
    return false;
  slip.reserve(m.ctx, 3 * entries * f, m.largest);
  m.forget(slip);
  if (entries == 0) return true;
  cl_kernel k = m.kernel(m.load_pair_slips, "gr_k_load_pair_slips");
  if (!m.lookup_by_id(k, slip, 3 * entries, same, true, n, id, hist_id, hist_n, table_size))
    return true;
  const int count = static_cast<int>(n);
  set_buffer(k, 0, &m.nb_offsets);
  set_buffer(k, 1, &m.nb_indices);
  set_buffer(k, 5, &m.hist_offsets);
  set_buffer(k, 6, &m.hist_indices);
  set_buffer(k, 7, same ? nullptr : &m.hist_id);
  set_buffer(k, 8, &m.hist_slip);
  set_buffer(k, 9, &slip);
  check(clSetKernelArg(k, 10, sizeof(int), &count), "clSetKernelArg");
  m.launch(k, n);
  return true;
}

void Iterations::fetch_pair_history(float* out, NeighborList* rows) {
  Impl& m = *impl_;
  m.download(m.hist_slip, out, 3 * m.hist_entries * sizeof(float));
  if (!rows) return;
  rows->offsets.resize(m.hist_grains + 1);
  rows->indices.resize(m.hist_entries);
  m.download(m.hist_offsets, rows->offsets.data(), rows->offsets.size() * sizeof(gr_uint));
  if (m.hist_entries > 0)
    m.download(m.hist_indices, rows->indices.data(), m.hist_entries * sizeof(gr_uint));
}

void Iterations::fetch_pair_sums(gr_uint* out, size_t entries) {
  Impl& m = *impl_;
  m.download(m.pair_sum, out, entries * sizeof(gr_uint));
}

void Iterations::fetch_pair_slips(float* out, size_t entries) {
  Impl& m = *impl_;
  m.download(m.arrays[kPairSlip], out, 3 * entries * sizeof(float));
}

}  // namespace grains::opencl
