// The grains node's sleeping test on the device (kernels/sleep.h, grains.cl's gr_k_sleep_*):
// the state stays here between substeps, the starts and the sleepers' fixed masses are made
// here before the substep and the end is settled here after it, so that neither the positions
// nor the velocities cross for it.
#include <algorithm>
#include <cstdint>
#include <utility>

#include "nodes/grains/opencl/device_state.h"
#include "nodes/grains/opencl/iterations.h"

namespace grains::opencl {

bool Iterations::sleeps_there() const {
  Impl& m = *impl_;
  m.open_neighbours();  // the sleeping kernels sit beside the rows' (cl_khr_fp64)
  return m.sleep_rows && !m.host_sleep;
}

bool Iterations::sleep_begin(const gr_grains& g, const gr_sleep_params& sp, size_t n,
                             const float* P, const uint8_t* can, const float* force,
                             bool force_uniform, const SleepState* state, bool* changed) {
  Impl& m = *impl_;
  m.sleep_begun = false;
  // a start from the last end in carry_start's order, or in the end's
  const bool reordered = !P && m.carry_from_n == n;
  if (n == 0 || !sleeps_there() || (!P && !reordered && m.carry_n != n) ||
      (!state && m.sleep_n != n))
    return false;
  const size_t f = sizeof(float);
  if (state) {
    m.sleep_n = m.asleep_n = 0;  // (a new order, maybe: no flags to compare with)
    m.upload(m.sleep_time, state->time, n * f);
    m.upload(m.sleep_anchor, state->anchor, 3 * n * f);
    m.upload(m.sleep_accel, state->accel, 3 * n * f);
    m.upload(m.sleep_contacts, state->contacts, n * sizeof(int32_t));
    m.sleep_n = n;
  }
  // what predict() and the solve read, sent now and left as this call makes them
  m.upload_once(m.arrays[kMass], g.mass, n * f);
  m.upload_once(m.arrays[kInvMass], g.inv_mass, n * f);
  m.upload_once(m.arrays[kRadius], g.radius, n * f);
  m.upload_once(m.velocity, g.v, 3 * n * f);
  m.upload_once(m.force, force, (force_uniform ? 3 : 3 * n) * f);
  m.sleep_start.reserve(m.ctx, 3 * n * f, m.largest);
  m.sleep_start_v.reserve(m.ctx, 3 * n * f, m.largest);
  m.sleep_mass.reserve(m.ctx, n * f, m.largest);
  if (m.sleep_asleep.capacity < n) m.asleep_n = 0;  // grown: the last call's flags are gone
  m.sleep_asleep.reserve(m.ctx, n, m.largest);
  if (P) m.upload(m.sleep_start, P, 3 * n * f);
  m.sleep_can_all = can == nullptr;
  if (can) m.upload(m.sleep_can, can, n);
  const int zero = 0;
  m.sleep_changed.reserve(m.ctx, sizeof zero, m.largest);
  m.send(m.sleep_changed, &zero, sizeof zero);
  m.sleep_force_uniform = force_uniform;
  m.sleep_force = force != nullptr;
  // sp, P, start, v, start_v, mass, awake, inv_mass, radius, can, force, force_uniform, time,
  // anchor, accel, asleep, prev, changed, n, from
  cl_kernel k = m.kernel(m.sleep_begin, "gr_k_sleep_begin");
  const int count = static_cast<int>(n), uniform = force_uniform ? 1 : 0,
            prev = m.asleep_n == n ? 1 : 0;
  arg(k, 0, sp), arg(k, 1, P ? m.sleep_start : m.carry_P), arg(k, 2, m.sleep_start);
  arg(k, 3, m.velocity), arg(k, 4, m.sleep_start_v), arg(k, 5, m.arrays[kMass]);
  arg(k, 6, m.sleep_mass), arg(k, 7, m.arrays[kInvMass]), arg(k, 8, m.arrays[kRadius]);
  set_buffer(k, 9, can ? &m.sleep_can : nullptr);
  set_buffer(k, 10, force ? &m.force : nullptr);
  arg(k, 11, uniform), arg(k, 12, m.sleep_time), arg(k, 13, m.sleep_anchor);
  arg(k, 14, m.sleep_accel), arg(k, 15, m.sleep_asleep), arg(k, 16, prev);
  arg(k, 17, m.sleep_changed), arg(k, 18, count);
  set_buffer(k, 19, reordered ? &m.carry_from : nullptr);
  m.launch(k, n);
  int flag = 0;
  m.download(m.sleep_changed, &flag, sizeof flag);
  *changed = flag != 0;
  m.asleep_n = n;
  m.sleep_begun = true;
  return true;
}

bool Iterations::sleep_carry(size_t n) {
  Impl& m = *impl_;
  if (n == 0 || !sleeps_there() || m.sleep_n == 0 || m.sleep_n != m.carry_n) return false;
  m.asleep_n = 0;  // a new order, maybe: no flags to compare with (as for a state sent)
  if (m.carry_from_n == 0) return m.sleep_n == n;
  if (m.carry_from_n != n) return false;
  const size_t f = sizeof(float);
  m.carry_time.reserve(m.ctx, n * f, m.largest);
  m.carry_anchor.reserve(m.ctx, 3 * n * f, m.largest);
  m.carry_accel.reserve(m.ctx, 3 * n * f, m.largest);
  m.carry_contacts.reserve(m.ctx, n * sizeof(int32_t), m.largest);
  // from, time, anchor, accel, contacts, to_time, to_anchor, to_accel, to_contacts, n
  cl_kernel k = m.kernel(m.sleep_carry, "gr_k_sleep_carry");
  const int count = static_cast<int>(n);
  arg(k, 0, m.carry_from), arg(k, 1, m.sleep_time), arg(k, 2, m.sleep_anchor);
  arg(k, 3, m.sleep_accel), arg(k, 4, m.sleep_contacts), arg(k, 5, m.carry_time);
  arg(k, 6, m.carry_anchor), arg(k, 7, m.carry_accel), arg(k, 8, m.carry_contacts);
  arg(k, 9, count);
  m.launch(k, n);
  std::swap(m.sleep_time, m.carry_time);
  std::swap(m.sleep_anchor, m.carry_anchor);
  std::swap(m.sleep_accel, m.carry_accel);
  std::swap(m.sleep_contacts, m.carry_contacts);
  m.sleep_n = n;
  return true;
}

bool Iterations::sleep_end(const gr_sleep_params& sp, size_t n, bool device_rows,
                           const NeighborList* rows, const gr_collider* colliders,
                           size_t collider_count) {
  Impl& m = *impl_;
  if (!m.sleep_begun || n == 0 || m.asleep_n != n || m.sleep_n != n || m.carry_n != n ||
      m.carry_v_n != n || (device_rows && !(m.rows_found && m.rows_grains == n)))
    return false;
  m.sleep_begun = false;
  const Buffer* offsets = nullptr;
  const Buffer* indices = nullptr;
  if (device_rows) {
    offsets = &m.nb_offsets, indices = &m.nb_indices;
  } else if (rows && rows->offsets.size() == n + 1) {
    m.upload(m.sleep_offsets, rows->offsets.data(), (n + 1) * sizeof(gr_uint));
    m.upload(m.sleep_indices, rows->indices.data(),
             std::max<size_t>(rows->indices.size(), 1) * sizeof(gr_uint));
    offsets = &m.sleep_offsets, indices = &m.sleep_indices;
  }
  m.sleep_woken.reserve(m.ctx, n, m.largest);
  m.sleep_fast.reserve(m.ctx, n, m.largest);
  const int count = static_cast<int>(n), uniform = m.sleep_force_uniform ? 1 : 0;
  const Buffer* force = m.sleep_force ? &m.force : nullptr;
  // sp, P, v, start, start_v, awake, radius, force, force_uniform, asleep, woken, fast, n
  cl_kernel settle = m.kernel(m.sleep_settle, "gr_k_sleep_settle");
  arg(settle, 0, sp), arg(settle, 1, m.carry_P), arg(settle, 2, m.end_v);
  arg(settle, 3, m.sleep_start), arg(settle, 4, m.sleep_start_v), arg(settle, 5, m.sleep_mass);
  arg(settle, 6, m.arrays[kRadius]), set_buffer(settle, 7, force), arg(settle, 8, uniform);
  arg(settle, 9, m.sleep_asleep), arg(settle, 10, m.sleep_woken), arg(settle, 11, m.sleep_fast);
  arg(settle, 12, count);
  m.launch(settle, n);
  // (sent once a substep, with the planes)
  if (!colliders) collider_count = 0;
  if (collider_count)
    m.upload_once(m.plane_colliders, colliders, collider_count * sizeof(gr_collider));
  const int count_colliders = static_cast<int>(collider_count);
  // sp, P, v, radius, offsets, indices, awake, can, force, force_uniform, time, anchor, accel,
  // contacts, asleep, woken, fast, n, colliders, collider_count, meshes
  cl_kernel update = m.kernel(m.sleep_update, "gr_k_sleep_update");
  arg(update, 0, sp), arg(update, 1, m.carry_P), arg(update, 2, m.end_v);
  arg(update, 3, m.arrays[kRadius]), set_buffer(update, 4, offsets);
  set_buffer(update, 5, indices), arg(update, 6, m.sleep_mass);
  set_buffer(update, 7, m.sleep_can_all ? nullptr : &m.sleep_can), set_buffer(update, 8, force);
  arg(update, 9, uniform), arg(update, 10, m.sleep_time), arg(update, 11, m.sleep_anchor);
  arg(update, 12, m.sleep_accel), arg(update, 13, m.sleep_contacts);
  arg(update, 14, m.sleep_asleep), arg(update, 15, m.sleep_woken), arg(update, 16, m.sleep_fast);
  arg(update, 17, count), set_buffer(update, 18, collider_count ? &m.plane_colliders : nullptr);
  arg(update, 19, count_colliders);
  set_buffer(update, 20, collider_count ? m.meshes() : nullptr);  // (set_meshes)
  m.launch(update, n);
  return true;
}

bool Iterations::fetch_sleep(float* time, float* anchor, float* accel, int32_t* contacts,
                             size_t n) {
  Impl& m = *impl_;
  if (m.sleep_n != n) return false;
  const size_t f = sizeof(float);
  m.download(m.sleep_time, time, n * f);
  m.download(m.sleep_anchor, anchor, 3 * n * f);
  m.download(m.sleep_accel, accel, 3 * n * f);
  m.download(m.sleep_contacts, contacts, n * sizeof(int32_t));
  return true;
}

}  // namespace grains::opencl
