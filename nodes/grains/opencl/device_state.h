// The OpenCL device's state, shared by the files that launch its kernels (iterations.cpp: the
// solves and passes; neighbours.cpp: the neighbour rows): the context, queue and program, the
// kernels and the device buffers, which keep their size from call to call.
#pragma once
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "nodes/grains/kernels/grid.h"
#include "nodes/grains/opencl/cl_program.h"
#include "nodes/grains/opencl/iterations.h"

namespace grains::opencl {

// the kernels take gr_params by value: plain 4-byte fields, the same layout on both sides
static_assert(sizeof(gr_params) % 4 == 0, "gr_params holds 4-byte fields only");

inline void check(cl_int status, const char* what) {
  if (status != CL_SUCCESS)
    throw std::runtime_error(std::string("OpenCL: ") + what + " failed (" + std::to_string(status) +
                             ")");
}

inline std::string mib(size_t bytes) {
  char text[64];
  std::snprintf(text, sizeof text, "%.1f MiB", static_cast<double>(bytes) / (1024.0 * 1024.0));
  return text;
}

// A device buffer grown on demand (never shrunk: the grains' counts vary from substep to substep).
struct Buffer {
  cl_mem mem = nullptr;
  size_t capacity = 0;
  // `largest`: the most bytes one buffer of the device may hold (Impl::largest)
  void reserve(cl_context ctx, size_t bytes, size_t largest) {
    bytes = std::max<size_t>(bytes, 4);
    if (bytes <= capacity) return;
    // a driver need not refuse a larger one: PoCL 3.1 took 4.9 GB with a 4 GiB limit and its
    // copy into it crashed
    if (bytes > largest)
      throw std::runtime_error(
          "use_opencl: the substep needs a device buffer of " + mib(bytes) +
          ", more than the device's largest, " + mib(largest) +
          " (CL_DEVICE_MAX_MEM_ALLOC_SIZE or GRAINS_OPENCL_MAX_BUFFER_MIB): "
          "too many grains for this device; run them on the CPU (use_opencl off)");
    release();
    cl_int status = CL_SUCCESS;
    mem = clCreateBuffer(ctx, CL_MEM_READ_WRITE, bytes, nullptr, &status);
    check(status, "clCreateBuffer");
    capacity = bytes;
  }
  void release() {
    if (mem) clReleaseMemObject(mem);
    mem = nullptr;
    capacity = 0;
  }
};

// kernel k's argument `index`: a value, or a buffer's memory object
template <class T>
inline void arg(cl_kernel k, cl_uint index, const T& value) {
  check(clSetKernelArg(k, index, sizeof(T), &value), "clSetKernelArg");
}
inline void arg(cl_kernel k, cl_uint index, const Buffer& b) {
  arg(k, index, b.mem);
}
// a buffer argument, or null for a missing array (OpenCL 1.2: a null arg_value is a null pointer)
inline void set_buffer(cl_kernel k, cl_uint index, const Buffer* b) {
  cl_mem m = b ? b->mem : nullptr;
  check(clSetKernelArg(k, index, sizeof(cl_mem), b ? &m : nullptr), "clSetKernelArg");
}

// the per-grain arrays of gr_grains, in the kernels' argument order (GR_GRAINS_ARGS)
enum Array {
  kP,
  kRadius,
  kInvMass,
  kMass,
  kFriction,
  kRepulsionWeight,
  kRepulsionStiffness,
  kAttractionWeight,
  kAttractionStiffness,
  kNbrOffsets,
  kNbrIndices,
  kPairSlip,
  kPlaneOffsets,
  kPlane,
  kPlaneSlip,
  kConOffsets,
  kConOther,
  kConPrim,
  kRestLength,
  kConstraintWeight,
  kConstraintStiffness,
  kArrays
};
constexpr cl_uint kScalars = 3;  // uniform_radius, uniform_inv_mass, nbr_unconstrained
constexpr size_t kGroup = 64;    // work-items a work-group
constexpr cl_uint kFirstOwn = 1 + kArrays + kScalars;  // after prm, the arrays and the scalars

// one array of gr_grains on the host and how much of it the device reads
struct HostArray {
  const void* host;
  size_t bytes;
};
// g's arrays in Array order (null where g has none)
void grain_arrays(const gr_grains& g, const IterationSizes& size, HostArray* out);

struct Iterations::Impl {
  std::string name;
  cl_context ctx = nullptr;
  cl_command_queue queue = nullptr;
  cl_program program = nullptr;
  // others: gr_k_iterate again, for gauss_seidel's constraints and clumping (its own arguments)
  cl_kernel iterate = nullptr, friction = nullptr, pin = nullptr, others = nullptr,
            sequential = nullptr;
  Buffer arrays[kArrays];
  Buffer p, next, scratch, pair_sum, collider_sum, collider_dx, friction_dx;
  Buffer target, target_weight, target_stiffness;  // pins
  // gauss_seidel's contacts in parts of whole blocks, each within the largest buffer: part k
  // holds blocks [part_block[k], part_block[k + 1])
  std::vector<Buffer> seq;
  std::vector<size_t> part_block;
  // the blocks' waves (block_wave, wave_start) and the colours' blocks
  Buffer block_wave, wave_start, colour_blocks;
  // the work-items that share a block in a sweep (GRAINS_OPENCL_SWEEP_ITEMS, or by the device's
  // kind), and each sweep kernel's own limit (CL_KERNEL_WORK_GROUP_SIZE) once asked
  size_t sweep_items = 1;
  bool builds_contacts = true;  // GRAINS_OPENCL_HOST_CONTACTS unset or 0
  bool host_sleep = false;      // GRAINS_OPENCL_HOST_SLEEP=1
  std::vector<std::pair<cl_kernel, size_t>> group_limit;
  cl_device_id device = nullptr;
  // pre-stabilization's start positions, what carried contacts moved, their flags, and the
  // largest move of each block in a pass
  Buffer stable, carried, carried_flag, block_most;
  cl_kernel stabilize = nullptr;
  // the warm start's (kernels/warm.h) and its buffers: each contact's normal and factor, each
  // grain's velocity, repeated displacement, external step, balance and cold flag
  cl_kernel warm_open = nullptr, warm_factor = nullptr, warm_cut = nullptr, warm_balance = nullptr,
            warm_cold = nullptr, take_back = nullptr, warm_repeat = nullptr, warm_apply = nullptr;
  cl_kernel keep = nullptr;  // a resident contact list's loads kept (gr_k_keep)
  // the list built on the device (build_sequential): the kernels, the last list while the new
  // one looks its loads up there, each grain's count and offset, the table of the last list's
  // loaded contacts, the blocks' starts and links, a count of loaded contacts
  cl_kernel seq_count = nullptr, seq_fill = nullptr, seq_blocks = nullptr, seq_links = nullptr,
            seq_table = nullptr, seq_lookup = nullptr, seq_loaded = nullptr, seq_waves = nullptr,
            seq_wave_starts = nullptr;
  Buffer seq_old, seq_offsets, seq_table_slots, seq_block_start, seq_links_bits, seq_loaded_count,
      id, plane_collider, flag_copy, marks, wave_of, wave_ends, block_waves;
  bool built_flags = false;  // the built list's contacts have carried flags (a warm lookup)
  Buffer velocity, repeat, external, balance, cold, cut;
  std::vector<Buffer> normal, factor;  // by part of the contacts, as seq
  // the Jacobi path's: a pass, and the largest move's parts
  cl_kernel stabilize_grains = nullptr, largest_part = nullptr;
  Buffer moved, moved_part;
  // ... and where the start stays there (stabilize's `there`): the prediction it moves
  // (gr_k_shift, into `shifted`), and for how many grains `start` holds this substep's start as
  // it went up (0: none)
  cl_kernel shift = nullptr;
  Buffer shifted;
  // Chebyshev's step within run() (JacobiSolve::chebyshev_rho): the kernel, and the iterate
  // before the last where neither p nor next holds it
  cl_kernel chebyshev = nullptr;
  Buffer before;
  // the impact data (SubstepEnd::impact_collider): the kernels, and each grain's slots
  // and the filled ones packed for the host (gr_k_impact_pack: their count, slots and values)
  cl_kernel impact_loads = nullptr, impact_pack = nullptr;
  Buffer impact_collider, impact_impulse, impact_normal, impact_point, impact_count,
      impact_index, impact_value;
  std::vector<int32_t> impact_index_host;
  std::vector<float> impact_value_host;
  // rigid shape matching (SequentialContacts::shapes): the kernel and the components' arrays
  cl_kernel shapes = nullptr;
  Buffer shape_offsets, shape_members, shape_rest, shape_mass, shape_normal;
  uint64_t shape_generation = 0;  // of the components and rest offsets there (0: none)
  size_t shape_grains = 0;        // ... for this many grains
  size_t start_kept = 0;
  // the Jacobi path's contact history (history.cpp, kernels/history.h): the kernels, the slips
  // the last save wrote (hist_entries of them, of hist_grains grains) with the rows they belong
  // to, the last substep's ids and each id's index there
  cl_kernel save_pair_slips = nullptr, history_table_kernel = nullptr, load_pair_slips = nullptr;
  Buffer hist_slip, hist_offsets, hist_indices, hist_id, hist_table;
  size_t hist_entries = 0, hist_grains = 0;
  bool hist_saved = false;  // hist_slip and its rows hold the last save's
  // hist_table holds this substep's ids' indices in the last substep (history_table())
  bool table_made = false;
  // the collider planes' saved slips (save_plane_history: an entry each, brought back, or kept
  // with the planes' rows, colliders and summed normal corrections they belong to, of
  // hist_plane_grains grains and hist_plane_entries entries) and the kernel that carries them
  // into the next substep's planes (load_plane_history)
  cl_kernel save_plane_slips = nullptr, load_plane_slips = nullptr;
  Buffer plane_saved, hist_plane_offsets, hist_plane_which, hist_plane_sum;
  size_t hist_plane_entries = 0, hist_plane_grains = 0;
  bool hist_planes_saved = false;
  // what the save and the load send, staged (held: a write reads them late, and the host
  // rewrites its arrays before the next call): the positions, the pair sums, the saved ids
  std::vector<float> hist_p_host;
  std::vector<gr_uint> hist_sums_host;
  std::vector<int> hist_id_host;
  // the most bytes one buffer may hold: the device's CL_DEVICE_MAX_MEM_ALLOC_SIZE, or less
  // when GRAINS_OPENCL_MAX_BUFFER_MIB says so
  size_t largest = 0;
  // the neighbour rows (neighbours.cpp): their kernels exist when the device has double
  // precision (the pair test's), else the host finds the rows
  cl_kernel bounds = nullptr, cell_count = nullptr, cell_place = nullptr, row_count = nullptr,
            row_fill = nullptr, scan_blocks = nullptr, scan_sums = nullptr, scan_apply = nullptr;
  Buffer nb_P, nb_radius, nb_part, nb_key, nb_count, nb_cursor, nb_grains, nb_sorted, nb_offsets,
      nb_keys, nb_indices, nb_sums;
  bool rows_found = false;  // nb_offsets and nb_indices hold the rows the last search gave
  size_t rows_grains = 0;   // the grains of those rows
  size_t searched_n = 0;    // nb_P holds the positions the last search took, of this many grains
  // what the host reads along the rows (kernels/row_stats.h): the kernels, the positions they
  // read (the radii: arrays[kRadius] or nb_radius), each run's results; the sleeping test's
  // kernel, its fast flags and its words; the Verlet test's kernel (the rows' positions: nb_P)
  cl_kernel row_overlaps = nullptr, row_reach = nullptr, sleep_rows = nullptr;
  cl_kernel rows_moved = nullptr, row_longest = nullptr;
  Buffer stats_P, stats_part, sleep_fast, sleep_out;
  // the substep's end (gr_k_finish), which writes the grains' positions into stats_P: for how
  // many grains it last did (0: stats_P holds positions sent since, or none); the grains the
  // host then changed go up through patch_index and patch_values (patch_positions). The final
  // collision test there (gr_k_final_collision) reads the start as it went up, kept in `start`
  // where pre-stabilization replaces it.
  cl_kernel finish = nullptr, scatter3 = nullptr, final_collision = nullptr;
  size_t written_n = 0;
  Buffer force, end_v, patch_index, patch_values, start;
  // what the last end there wrote, kept for the next substep's start (Iterations::carry_start):
  // the world positions of carry_n grains (0: none) and, for carry_v_n grains, the velocities
  // (in end_v, which only the end writes)
  cl_kernel carry = nullptr;
  Buffer carry_P, carry_from;  // carry_from: each grain's index in that end (a new order)
  // the sleeping test (opencl/sleep.cpp): its kernels, the state of sleep_n grains (time,
  // anchor, accel, contacts), the last sleep_begin's starts, start velocities, masses awake,
  // whether each may sleep and sleeps (of asleep_n grains), the end's woken and `changed`
  // flags, and rows sent from the host; the state carried into a new order through carry_from
  // (Iterations::sleep_carry: the carry_ arrays, then swapped)
  cl_kernel sleep_begin = nullptr, sleep_settle = nullptr, sleep_update = nullptr;
  cl_kernel sleep_carry = nullptr;
  Buffer sleep_time, sleep_anchor, sleep_accel, sleep_contacts, sleep_start, sleep_start_v,
      sleep_mass, sleep_can, sleep_asleep, sleep_woken, sleep_changed, sleep_offsets,
      sleep_indices, carry_time, carry_anchor, carry_accel, carry_contacts;
  size_t sleep_n = 0, asleep_n = 0;
  size_t carry_from_n = 0;  // carry_from holds this substep's order, of this many grains
  bool sleep_can_all = true, sleep_force = false, sleep_force_uniform = false;
  bool sleep_begun = false;  // sleep_begin ran this substep
  // what the last end there wrote, measured there (Iterations::end_bounds): the kernel, each
  // work-item's box and flag
  cl_kernel end_bounds = nullptr;
  Buffer end_part;
  // error control's motion measure of that end (Iterations::motion): the kernel, each
  // work-item's two doubles
  cl_kernel motion = nullptr;
  Buffer motion_part;
  size_t carry_n = 0, carry_v_n = 0;
  // the substep's predicted positions made there (Iterations::predict, gr_k_predict), which the
  // search of rows or planes and the solve take
  cl_kernel predict = nullptr;
  Buffer predicted;
  std::vector<float> patch_host[2];  // the values patch() sends (held: a write reads them late)
  // the grains `index` lists of `to` (3 floats a grain) take their values in host array P (n x
  // 3), sent alone through patch_index (already there with index_there) and patch_values,
  // staged in patch_host[slot]
  void patch(Buffer& to, const float* P, const std::vector<gr_uint>& index, bool index_there,
             int slot);
  // n grains' positions P (n x 3) into stats_P: only those written_there lists go up when the
  // finish wrote n grains there (Iterations::row_overlaps), else all of them
  void stats_positions(const float* P, size_t n, const std::vector<gr_uint>* written_there);
  // the collider planes (planes.cpp): the kernels, the colliders and the predicted positions
  // they read (the search's nb_P when it took these; the start positions, radii and inverse
  // masses are arrays[kP], [kRadius] and [kInvMass], or the search's nb_radius); the rows and
  // entries go to arrays[kPlaneOffsets], arrays[kPlane] and plane_collider
  cl_kernel plane_count = nullptr, plane_fill = nullptr;
  Buffer plane_colliders, plane_p;
  // a rebuild during run()'s iterations (JacobiSolve::rebuild, `rebuilding` while it runs): the
  // planes' start positions, radii and inverse masses where the arrays the passes read hold
  // others (sent once a substep); the carry kernels (kernels/history.h) and the rows and
  // colliders of the planes before it (hold_planes: of held_planes_n grains), and the buffers
  // the carried sums and slips go to, which then change places with those the passes read
  bool rebuilding = false;
  Buffer rebuild_P, rebuild_radius, rebuild_inv_mass;
  cl_kernel carry_pairs = nullptr, carry_planes = nullptr;
  Buffer held_plane_offsets, held_plane_which, carried_sum, carried_slip;
  size_t held_planes_n = 0;
  // the colliders' meshes as words (Iterations::set_meshes, engine/mesh_query.h), which the
  // planes, the final collision test and the sleeping test read with plane_colliders; the
  // meshes they are (mesh_key, null for an analytic collider) and whether one is a mesh
  Buffer mesh_words;
  std::vector<int32_t> mesh_host;  // what went up, while it goes
  std::vector<std::shared_ptr<const MeshShape>> mesh_key;
  bool any_meshes = false;
  const Buffer* meshes() const { return any_meshes ? &mesh_words : nullptr; }
  size_t plane_entries = 0;  // the entries the last find_planes found
  size_t plane_grains = 0;   // and the grains it searched
  // the rows and colliders of the planes a contact list was built from (keep_planes), for
  // kept_planes_n grains (0: none) and kept_plane_entries entries, which gr_k_plane_same
  // compares a search's with (its answer in plane_differs)
  cl_kernel plane_same = nullptr;
  Buffer kept_plane_offsets, kept_plane_which, plane_differs;
  size_t kept_planes_n = 0, kept_plane_entries = 0;
  // the rows and colliders of the last find_planes() copied there into offsets and which
  // (keep_planes, hold_planes)
  void copy_plane_rows(Buffer& offsets, Buffer& which);

  ~Impl() {
    // what was enqueued and not waited for runs to its end first: PoCL compiles a kernel on its
    // own thread at the kernel's first run, and a program that exited meanwhile crashed in LLVM
    // (a released queue does not wait for its commands)
    if (queue) clFinish(queue);
    for (Buffer& b : arrays) b.release();
    for (Buffer* b : {&p, &next, &scratch, &pair_sum, &collider_sum, &collider_dx, &friction_dx,
                      &target, &target_weight, &target_stiffness, &block_wave, &wave_start,
                      &colour_blocks, &stable, &carried, &carried_flag, &block_most, &moved,
                      &moved_part, &velocity, &repeat, &external, &balance, &cold, &cut,
                      &seq_old, &seq_offsets, &seq_table_slots, &seq_block_start, &seq_links_bits,
                      &seq_loaded_count, &id, &plane_collider, &flag_copy, &marks, &wave_of,
                      &wave_ends, &block_waves, &hist_slip, &hist_offsets, &hist_indices,
                      &hist_id, &hist_table, &plane_saved, &hist_plane_offsets,
                      &hist_plane_which, &hist_plane_sum, &shifted, &before, &rebuild_P,
                      &rebuild_radius, &rebuild_inv_mass, &held_plane_offsets,
                      &held_plane_which, &carried_sum, &carried_slip})
      b->release();
    for (std::vector<Buffer>* parts : {&seq, &normal, &factor})
      for (Buffer& b : *parts) b.release();
    for (Buffer* b : {&nb_P, &nb_radius, &nb_part, &nb_key, &nb_count, &nb_cursor, &nb_grains,
                      &nb_sorted, &nb_offsets, &nb_keys, &nb_indices, &nb_sums, &stats_P,
                      &stats_part, &sleep_fast, &sleep_out, &plane_colliders, &plane_p, &mesh_words,
                      &force, &end_v, &patch_index, &patch_values, &start, &carry_P, &end_part,
                      &carry_from, &sleep_time, &sleep_anchor, &sleep_accel,
                      &sleep_contacts, &sleep_start, &sleep_start_v, &sleep_mass, &sleep_can,
                      &sleep_asleep, &sleep_woken, &sleep_changed, &sleep_offsets,
                      &sleep_indices, &carry_time, &carry_anchor, &carry_accel,
                      &carry_contacts, &motion_part,
                      &predicted, &kept_plane_offsets, &kept_plane_which, &plane_differs,
                      &shape_offsets, &shape_members, &shape_rest, &shape_mass, &shape_normal,
                      &impact_collider, &impact_impulse, &impact_normal, &impact_point,
                      &impact_count, &impact_index, &impact_value})
      b->release();
    for (cl_kernel k : {iterate, friction, pin, others, sequential, stabilize, warm_open,
                        warm_factor, warm_cut, warm_balance, warm_cold, take_back, warm_repeat,
                        warm_apply, keep, seq_count, seq_fill, seq_blocks, seq_links,
                        seq_table, seq_lookup, seq_loaded, seq_waves, seq_wave_starts,
                        stabilize_grains, largest_part, bounds, cell_count,
                        cell_place, row_count, row_fill, scan_blocks, scan_sums, scan_apply,
                        row_overlaps, row_reach, sleep_rows, plane_count, plane_fill,
                        finish, scatter3, final_collision, carry, predict, plane_same,
                        rows_moved, end_bounds, sleep_begin, sleep_settle, sleep_update,
                        sleep_carry, motion, save_pair_slips, history_table_kernel,
                        load_pair_slips, row_longest, save_plane_slips, load_plane_slips,
                        shift, chebyshev, shapes, impact_loads, impact_pack, carry_pairs,
                        carry_planes})
      if (k) clReleaseKernel(k);
    if (program) clReleaseProgram(program);
    if (queue) clReleaseCommandQueue(queue);
    if (ctx) clReleaseContext(ctx);
  }

  // what has crossed since the device was opened (Iterations::traffic): every transfer goes
  // through upload(), send() or download()
  Traffic traffic;
  // The arrays sent this substep that hold the same values through it (a grain's radius, mass,
  // start position, attributes, pins; Iterations::begin_substep forgets them): each buffer's
  // host array and bytes. upload_once() sends one only when its buffer holds another; any other
  // transfer into a buffer forgets what it held.
  struct Once {
    const Buffer* buffer;
    cl_mem mem;  // the buffer's memory when it took them (a larger one holds nothing of them)
    const void* host;
    size_t bytes;
  };
  std::vector<Once> once;
  void forget(const Buffer& b) {
    auto of_b = [&](const Once& h) { return h.buffer == &b; };
    once.erase(std::remove_if(once.begin(), once.end(), of_b), once.end());
  }
  // whether b holds these bytes of this host array from earlier in the substep
  bool holds(const Buffer& b, const void* host, size_t bytes, size_t device_bytes = 0) const {
    for (const Once& h : once)
      if (h.buffer == &b && h.mem == b.mem && h.host == host && h.bytes == bytes &&
          b.capacity >= std::max(bytes, device_bytes))
        return true;
    return false;
  }
  // upload(), skipped when b holds() them
  void upload_once(Buffer& b, const void* host, size_t bytes, size_t device_bytes = 0) {
    if (!host || holds(b, host, bytes, device_bytes)) return;
    upload(b, host, bytes, device_bytes);
    once.push_back({&b, b.mem, host, bytes});
  }
  // upload_once() of a host array whose bytes `from` holds on the device already: copied there
  void copy_once(Buffer& b, const Buffer& from, const void* host, size_t bytes) {
    if (!host || holds(b, host, bytes)) return;
    b.reserve(ctx, bytes, largest);
    if (bytes > 0)
      check(clEnqueueCopyBuffer(queue, from.mem, b.mem, 0, 0, bytes, 0, nullptr, nullptr),
            "clEnqueueCopyBuffer");
    copied_once(b, host, bytes);
  }
  // upload_once()'s record that b holds the host array `host` (bytes of it) copied there on the
  // device from another buffer
  void copied_once(const Buffer& b, const void* host, size_t bytes) {
    forget(b);
    once.push_back({&b, b.mem, host, bytes});
  }
  // the substep's predicted positions where the last search of rows or planes took them or the
  // prediction made them (nb_P, plane_p or predicted), for p_taken_n grains
  Buffer* p_taken = nullptr;
  size_t p_taken_n = 0;
  // the buffer (p or next) that holds the positions the last run() ended with, for run_out_n
  // grains (0: none, or written since: upload_grains, begin_substep), which the contact
  // history's save takes there (save_pair_history)
  const Buffer* run_out = nullptr;
  size_t run_out_n = 0;

  // copies `bytes` of host memory to b (grown as needed); a null host array leaves b unset
  void upload(Buffer& b, const void* host, size_t bytes, size_t device_bytes = 0) {
    if (!host) return;
    b.reserve(ctx, std::max(bytes, device_bytes), largest);
    send(b, host, bytes);
  }
  // copies `bytes` of host memory to the start of b, which holds them already. Memory that is
  // one 4-byte word over and over (equal radii or masses, an attribute with one value) is
  // filled there from that word instead: only the word crosses.
  void send(Buffer& b, const void* host, size_t bytes) {
    if (bytes == 0) return;
    forget(b);
    uint32_t word = 0;
    if (repeated(host, bytes, &word)) {
      check(clEnqueueFillBuffer(queue, b.mem, &word, sizeof word, 0, bytes, 0, nullptr, nullptr),
            "clEnqueueFillBuffer");
      traffic.sent += sizeof word;
    } else {
      check(clEnqueueWriteBuffer(queue, b.mem, CL_FALSE, 0, bytes, host, 0, nullptr, nullptr),
            "clEnqueueWriteBuffer");
      traffic.sent += bytes;
    }
    ++traffic.uploads;
  }
  // whether `bytes` of host memory (64 or more) are one 4-byte word, *word, over and over
  static bool repeated(const void* host, size_t bytes, uint32_t* word) {
    if (bytes < 64 || bytes % sizeof(uint32_t) != 0) return false;
    const unsigned char* at = static_cast<const unsigned char*>(host);
    std::memcpy(word, at, sizeof *word);
    for (size_t k = sizeof *word; k < bytes; k += sizeof *word) {
      uint32_t next;
      std::memcpy(&next, at + k, sizeof next);
      if (next != *word) return false;
    }
    return true;
  }
  // `bytes` of b from byte `offset` on into host memory (waits for them)
  void download(const Buffer& b, void* host, size_t bytes, size_t offset = 0) {
    if (!host || bytes == 0) return;
    check(clEnqueueReadBuffer(queue, b.mem, CL_TRUE, offset, bytes, host, 0, nullptr, nullptr),
          "clEnqueueReadBuffer");
    traffic.received += bytes;
    ++traffic.downloads;
  }

  // g's arrays (grain_arrays, into a) to `arrays` and the positions p to `p`, once a call;
  // `next` made room for the passes that swap with p. rows_only: of the arrays only the
  // neighbour rows go (the others went with the call before, unchanged)
  void upload_grains(const gr_grains& g, const IterationSizes& size, const float* positions,
                     HostArray* a, bool rows_only = false);
  // rows whose indices stayed where the search left them (size.rows_there, no host copy: a's
  // indices null, its offsets not): the search's buffer stands in a for the host array that
  // upload_once()'s records name, so that they are copied there and bound
  void stand_in_rows(const IterationSizes& size, HostArray* a) const;
  // kernel k's first arguments: prm, the arrays `a` holds (null where it has none) and g's scalars
  void set_grains(cl_kernel k, const gr_params& prm, const gr_grains& g, const HostArray* a);
  // the pins' arguments (g.targetP and its arrays uploaded), and one pin projection of x
  void set_pins(const gr_grains& g, const gr_params& prm, size_t n);
  void project_pins(Buffer* x, size_t global);
  // the shapes' arguments (their arrays uploaded where they are not there; normal: the normal
  // sums' buffer, null: none), and one projection of x
  void set_shapes(const ShapeArrays& sh, const gr_params& prm, const gr_grains& g,
                  const HostArray* inputs, Buffer* normal, size_t n);
  void project_shapes(Buffer* x, size_t components);
  // hist_table: each id of the n grains now (id, null: their indices) at its grain's index in
  // the last substep's hist_n (hist_id, below table_size), once a substep (table_made)
  void history_table(size_t n, const int* id, const int* hist_id, size_t hist_n,
                     size_t table_size);
  // a lookup of carried slips (gr_k_load_pair_slips, gr_k_load_plane_slips: k) by the grains'
  // ids, or `same` (each grain its own index there): the table and k's arguments 2 to 4 (id,
  // table, its size); false where there is nothing to look up by (no ids, or not `usable`), the
  // `floats` of slip then 0
  bool lookup_by_id(cl_kernel k, Buffer& slip, size_t floats, bool same, bool usable, size_t n,
                    const int* id, const int* hist_id, size_t hist_n, size_t table_size);
  // s's contacts to `seq` in parts of whole blocks (part_block), with their blocks and colours
  void upload_contacts(const SequentialContacts& s);
  // k over `items` work-items (at least one) in work-groups of kGroup: the kernels return at
  // once past their count
  void launch(cl_kernel k, size_t items);
  // The substep's end from the positions `result` (SubstepEnd: gr_k_finish, then
  // the final collision test from the start start_there holds), kept for carry_start and
  // brought back unless it stays; the start velocities are there already when velocity_there,
  // else g.v goes up (once)
  void finish_substep(const gr_grains& g, const gr_params& prm, const HostArray* inputs,
                      Buffer* result, const SubstepEnd& e, bool velocity_there,
                      Buffer* start_there, size_t n);
  // the impact data gr_k_final_collision made (`slots` of them) into end's arrays: the filled slots
  // packed there (gr_k_impact_pack) and brought back, the others -1 and zeros
  void fetch_impacts(const SubstepEnd& end, size_t slots);
  // n grains' positions (3 n floats) from `from` into `to`, and a zero past them, as an upload
  // of positions has (one float past the last grain, which the contact loop's block loads read)
  void copy_positions(Buffer& to, const Buffer& from, size_t n);
  // s's blocks' waves and colours alone
  void upload_blocks(const SequentialContacts& s);
  // the contacts `seq` holds when it is one part (held_whole): how many
  size_t held = 0;
  bool held_whole = false;
  size_t grains = 0;  // the grains of the list build_sequential built
  // kernel k's arguments that sweep_colour sets for each part: its contacts, the colour's first
  // block there (in s.colour_blocks), their count, the part's first contact
  struct PartArgs {
    static constexpr cl_uint kNoArg = ~cl_uint(0);
    cl_uint seq, first, count, base;
    cl_uint normal = kNoArg, factor = kNoArg;  // the part's normal and factor buffers, if taken
    cl_uint local_floats = kNoArg;             // a __local float a work-item, if taken
  };
  // launches k (a work-group a block, of sweep_items work-items or k's limit) over each part of
  // colour c's blocks
  void sweep_colour(cl_kernel k, PartArgs at, const SequentialContacts& s, size_t c);
  // s's contacts from the device (after upload_contacts)
  void download_contacts(const SequentialContacts& s);
  // `iterations` passes of gauss_seidel on the uploaded grains (inputs: upload_grains') and
  // contacts, from p; returns the buffer holding the result (p or next)
  Buffer* sequential_passes(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                            const SequentialContacts& s, int iterations, const HostArray* inputs);
  // launches the per-contact kernel k over each part of the contacts, its arguments seq_arg,
  // seq_arg + 1 and + 2 set to the part's contacts, its first contact's number and its count
  // (and normal_arg, factor_arg to the part's normal and factor)
  void each_part(cl_kernel k, cl_uint seq_arg, const SequentialContacts& s,
                 cl_uint normal_arg = PartArgs::kNoArg, cl_uint factor_arg = PartArgs::kNoArg);
  // k, created from the program the first time (name: its kernel's)
  cl_kernel kernel(cl_kernel& k, const char* name);
  // the neighbour kernels, when the program has them (a device with cl_khr_fp64)
  void open_neighbours();
  // an exclusive prefix sum of x's n counts in place, the total at x[n] (x holds n + 1)
  void scan(Buffer& x, size_t n);
};

}  // namespace grains::opencl
