// The neighbour rows on an OpenCL device (Iterations::find_neighbours; the kernels and why they
// give the CPU's rows: kernels/grid.h and grains.cl). The host reads back the bounding box (7
// floats a work-item of gr_k_bounds) to lay out the grid, and the row offsets to size the rows.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <vector>

#include "nodes/grains/opencl/device_state.h"

namespace grains::opencl {
namespace {

static_assert(sizeof(gr_grid) == 88,
              "gr_grid: the OpenCL C layout (8-byte fields, then two 4-byte)");

constexpr int64_t kCellMax = (int64_t(1) << 31) - 2;  // the most cells along an axis
constexpr size_t kBoundsItems = 16 * kGroup;          // gr_k_bounds' work-items
constexpr size_t kScanBlock = 1024;                   // counts a work-item of the prefix sum sums

// The grid over the box [lo, hi] of n grains with pair distances below t_max (kernels/grid.h):
// every axis dense when the box has at most 8 cells a grain, else wrapped on powers of two of at
// least 4 cells until about 4 cells a grain, the longest axis first.
gr_grid lay_out(const float lo[3], const float hi[3], float t_max, size_t n,
                const NeighborQuery& q) {
  gr_grid g{};
  const double h = double(t_max) * (1.0 + 1e-5);
  g.inv_h = 1.0 / h;
  g.qs = q.query_scale;
  g.max_neighbors = q.max_neighbors;
  double cells = 1;
  for (int a = 0; a < 3; ++a) {
    g.lo[a] = lo[a];
    const double e = std::floor((double(hi[a]) - double(lo[a])) * g.inv_h) + 1.0;
    g.ext[a] = e >= double(kCellMax) ? kCellMax : std::max<int64_t>(1, int64_t(e));
    cells *= double(g.ext[a]);
  }
  if (cells <= 8.0 * double(n) + 64.0) {
    for (int a = 0; a < 3; ++a) g.dim[a] = g.ext[a];
    return g;
  }
  int64_t target = 64;
  while (target < int64_t(4 * n)) target *= 2;
  for (int a = 0; a < 3; ++a) g.dim[a] = std::min<int64_t>(g.ext[a], 4);
  while (g.dim[0] * g.dim[1] * g.dim[2] < target) {
    int best = -1;
    double ratio = 1.0;
    for (int a = 0; a < 3; ++a) {
      const double r = double(g.ext[a]) / double(g.dim[a]);
      if (g.dim[a] < g.ext[a] && r > ratio) best = a, ratio = r;
    }
    if (best < 0) break;
    g.dim[best] = g.dim[best] * 2 >= g.ext[best] ? g.ext[best] : g.dim[best] * 2;
  }
  return g;
}

}  // namespace

void Iterations::Impl::open_neighbours() {
  if (scan_blocks) return;
  cl_int status = CL_SUCCESS;
  auto make = [&](const char* name) {
    cl_kernel k = clCreateKernel(program, name, &status);
    check(status, name);
    return k;
  };
  scan_blocks = make("gr_k_scan_blocks");
  scan_sums = make("gr_k_scan_sums");
  scan_apply = make("gr_k_scan_apply");
  // the program has the grid's kernels only where cl_khr_fp64 is defined (grains.cl)
  bounds = clCreateKernel(program, "gr_k_bounds", &status);
  if (status == CL_INVALID_KERNEL_NAME) {
    bounds = nullptr;
    return;
  }
  check(status, "gr_k_bounds");
  cell_count = make("gr_k_cell_count");
  cell_place = make("gr_k_cell_place");
  row_count = make("gr_k_row_count");
  row_fill = make("gr_k_row_fill");
  row_overlaps = make("gr_k_row_overlaps");
  row_reach = make("gr_k_row_reach");
  rows_moved = make("gr_k_rows_moved");
  row_longest = make("gr_k_row_longest");
  sleep_rows = make("gr_k_sleep_rows");
}

void Iterations::Impl::scan(Buffer& x, size_t n) {
  const size_t blocks = (n + kScanBlock - 1) / kScanBlock;
  if (blocks == 0) {
    const gr_uint zero = 0;
    send(x, &zero, sizeof zero);
    return;
  }
  nb_sums.reserve(ctx, (blocks + 1) * sizeof(gr_uint), largest);
  const int count = static_cast<int>(n), block = static_cast<int>(kScanBlock),
            nblocks = static_cast<int>(blocks);
  arg(scan_blocks, 0, x), arg(scan_blocks, 1, count), arg(scan_blocks, 2, block);
  arg(scan_blocks, 3, nb_sums), arg(scan_blocks, 4, nblocks);
  launch(scan_blocks, blocks);
  arg(scan_sums, 0, nb_sums), arg(scan_sums, 1, nblocks);
  launch(scan_sums, 1);
  arg(scan_apply, 0, x), arg(scan_apply, 1, count), arg(scan_apply, 2, block);
  arg(scan_apply, 3, nb_sums), arg(scan_apply, 4, nblocks);
  launch(scan_apply, blocks);
}

bool Iterations::find_neighbours(const float* P, const float* radius, size_t n,
                                 const NeighborQuery& q, NeighborList& out, bool indices_there,
                                 bool p_there) {
  Impl& m = *impl_;
  const size_t f = sizeof(float), u = sizeof(gr_uint);
  m.rows_found = false;
  m.rows_grains = n;
  // the rows copied from the last search's (Impl::upload_grains) are no longer the host's
  m.forget(m.arrays[kNbrOffsets]);
  m.forget(m.arrays[kNbrIndices]);
  m.searched_n = 0;
  if (n >= size_t(std::numeric_limits<int>::max()) / 3) return false;
  m.open_neighbours();
  if (!m.bounds) return false;
  if (n == 0) {
    out.offsets.assign(1, 0);
    out.indices.clear();
    return true;
  }
  // a buffer over the device's largest: the host finds the rows (the same rows) rather than
  // refuse the substep; the entries' keys are checked once their number is known
  if (4 * n * f > m.largest) return false;
  const int count = static_cast<int>(n);
  if (!(p_there && holds_prediction(n)))
    m.upload(m.nb_P, P, 3 * n * f);
  else if (m.p_taken != &m.nb_P)
    m.copy_positions(m.nb_P, *m.p_taken, n);
  m.upload_once(m.nb_radius, radius, n * f);  // (a rebuild's search takes them again)
  m.p_taken = &m.nb_P;
  m.p_taken_n = n;
  m.searched_n = n;

  // the finite positions' box and the largest radius
  m.nb_part.reserve(m.ctx, 7 * kBoundsItems * f, m.largest);
  arg(m.bounds, 0, m.nb_P), arg(m.bounds, 1, m.nb_radius), arg(m.bounds, 2, count),
      arg(m.bounds, 3, m.nb_part);
  m.launch(m.bounds, kBoundsItems);
  std::vector<float> part(7 * kBoundsItems);
  m.download(m.nb_part, part.data(), part.size() * f);
  const float inf = std::numeric_limits<float>::infinity();
  float lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf}, r_max = -inf;
  for (size_t w = 0; w < kBoundsItems; ++w) {
    for (int a = 0; a < 3; ++a)
      lo[a] = std::min(lo[a], part[7 * w + a]), hi[a] = std::max(hi[a], part[7 * w + 3 + a]);
    if (part[7 * w + 6] > r_max) r_max = part[7 * w + 6];
  }
  for (int a = 0; a < 3; ++a)
    if (!(lo[a] <= hi[a])) lo[a] = hi[a] = 0.0f;  // no finite coordinate
  // no pair's t = qs (ri + rj) exceeds the largest one's
  const float t_max = q.query_scale * (r_max + r_max);
  if (!(t_max > 0.0f)) {  // no pair passes the test
    out.offsets.assign(n + 1, 0);
    out.indices.clear();
    return true;
  }
  if (!std::isfinite(t_max)) return false;
  const gr_grid grid = lay_out(lo, hi, t_max, n, q);
  const size_t cells = size_t(grid.dim[0] * grid.dim[1] * grid.dim[2]);
  if ((cells + 1) * u > m.largest) return false;

  // the grains in their cells
  const gr_uint zero = 0;
  m.nb_key.reserve(m.ctx, n * u, m.largest);
  m.nb_count.reserve(m.ctx, (cells + 1) * u, m.largest);
  m.nb_cursor.reserve(m.ctx, cells * u, m.largest);
  m.nb_grains.reserve(m.ctx, n * u, m.largest);
  m.nb_sorted.reserve(m.ctx, 4 * n * f, m.largest);
  check(clEnqueueFillBuffer(m.queue, m.nb_count.mem, &zero, u, 0, (cells + 1) * u, 0, nullptr,
                            nullptr),
        "clEnqueueFillBuffer");
  check(clEnqueueFillBuffer(m.queue, m.nb_cursor.mem, &zero, u, 0, cells * u, 0, nullptr, nullptr),
        "clEnqueueFillBuffer");
  arg(m.cell_count, 0, grid), arg(m.cell_count, 1, m.nb_P), arg(m.cell_count, 2, count);
  arg(m.cell_count, 3, m.nb_key), arg(m.cell_count, 4, m.nb_count);
  m.launch(m.cell_count, n);
  m.scan(m.nb_count, cells);
  arg(m.cell_place, 0, m.nb_key), arg(m.cell_place, 1, count), arg(m.cell_place, 2, m.nb_count);
  arg(m.cell_place, 3, m.nb_cursor), arg(m.cell_place, 4, m.nb_grains);
  arg(m.cell_place, 5, m.nb_P), arg(m.cell_place, 6, m.nb_radius),
      arg(m.cell_place, 7, m.nb_sorted);
  m.launch(m.cell_place, n);

  // the rows: their lengths, offsets, then the rows themselves
  m.nb_offsets.reserve(m.ctx, (n + 1) * u, m.largest);
  for (cl_kernel k : {m.row_count, m.row_fill}) {
    arg(k, 0, grid), arg(k, 1, m.nb_P), arg(k, 2, m.nb_radius), arg(k, 3, m.nb_count);
    arg(k, 4, m.nb_grains), arg(k, 5, m.nb_sorted), arg(k, 6, count), arg(k, 7, m.nb_offsets);
  }
  m.launch(m.row_count, n);
  m.scan(m.nb_offsets, n);
  out.offsets.resize(n + 1);
  // rows that stay there: only their number of entries, the last offset, comes back
  if (indices_there)
    m.download(m.nb_offsets, out.offsets.data() + n, u, n * u);
  else
    m.download(m.nb_offsets, out.offsets.data(), (n + 1) * u);
  const size_t entries = out.offsets[n];
  out.indices.resize(indices_there ? 0 : entries);
  if (entries * sizeof(gr_pair_key_t) > m.largest) {
    out.offsets.clear();
    return false;
  }
  m.nb_indices.reserve(m.ctx, entries * u, m.largest);  // bound even when empty
  if (entries == 0) return m.rows_found = true;
  m.nb_keys.reserve(m.ctx, entries * sizeof(gr_pair_key_t), m.largest);
  arg(m.row_fill, 8, m.nb_keys), arg(m.row_fill, 9, m.nb_indices);
  m.launch(m.row_fill, n);
  if (!indices_there) m.download(m.nb_indices, out.indices.data(), entries * u);
  m.rows_found = true;
  return true;
}

void Iterations::carry_pairs(size_t n, size_t entries, bool slips) {
  Impl& m = *impl_;
  if (!m.rows_found || m.rows_grains != n)
    throw std::logic_error("carry_pairs: the device holds no such rows");
  const size_t u = sizeof(gr_uint);
  cl_kernel k = m.kernel(m.carry_pairs, "gr_k_carry_pairs");
  m.carried_sum.reserve(m.ctx, entries * u, m.largest);
  if (slips) m.carried_slip.reserve(m.ctx, 3 * entries * sizeof(float), m.largest);
  // the rows the passes read, their sums and slips; the search's rows; what they take; n
  arg(k, 0, m.arrays[kNbrOffsets]), arg(k, 1, m.arrays[kNbrIndices]), arg(k, 2, m.pair_sum);
  set_buffer(k, 3, slips ? &m.arrays[kPairSlip] : nullptr);
  arg(k, 4, m.nb_offsets), arg(k, 5, m.nb_indices), arg(k, 6, m.carried_sum);
  set_buffer(k, 7, slips ? &m.carried_slip : nullptr);
  arg(k, 8, static_cast<int>(n));
  m.launch(k, n);
  m.forget(m.pair_sum);
  std::swap(m.pair_sum, m.carried_sum);
  if (slips) {
    m.forget(m.arrays[kPairSlip]);
    std::swap(m.arrays[kPairSlip], m.carried_slip);
  }
}

void Iterations::fetch_rows(NeighborList& out) {
  Impl& m = *impl_;
  const size_t entries = out.offsets.empty() ? 0 : out.offsets.back();
  out.indices.resize(entries);
  // no search there, or one that found no pair to look for: its rows came back whole
  if (!m.rows_found && entries == 0) return;
  if (!m.rows_found || out.offsets.size() != m.rows_grains + 1)
    throw std::logic_error("fetch_rows: the device holds no such rows");
  m.download(m.nb_offsets, out.offsets.data(), out.offsets.size() * sizeof(gr_uint));
  if (entries) m.download(m.nb_indices, out.indices.data(), entries * sizeof(gr_uint));
}

bool Iterations::row_overlaps(const float* P, const float* radius, size_t n, RowOverlaps* out,
                              const std::vector<gr_uint>* written_there) {
  Impl& m = *impl_;
  if (!m.rows_found || !m.row_overlaps || n != m.rows_grains) return false;
  *out = RowOverlaps{};
  if (n == 0) return true;
  const size_t f = sizeof(float), runs = kBoundsItems;
  m.stats_positions(P, n, written_there);
  Buffer& rb = radius ? m.arrays[kRadius] : m.nb_radius;
  m.upload_once(rb, radius, n * f);
  m.stats_part.reserve(m.ctx, 3 * runs * sizeof(double), m.largest);
  const int count = static_cast<int>(n), items = static_cast<int>(runs);
  cl_kernel k = m.row_overlaps;
  arg(k, 0, m.stats_P), arg(k, 1, rb);
  arg(k, 2, m.nb_offsets), arg(k, 3, m.nb_indices), arg(k, 4, count), arg(k, 5, items);
  arg(k, 6, m.stats_part);
  m.launch(k, runs);
  std::vector<double> part(3 * runs);
  m.download(m.stats_part, part.data(), part.size() * sizeof(double));
  for (size_t w = 0; w < runs; ++w) {  // in run order: the host's sum, reassociated at the runs
    out->contacts += part[3 * w];
    out->largest = std::max(out->largest, static_cast<float>(part[3 * w + 1]));
    out->sum += part[3 * w + 2];
  }
  return true;
}

bool Iterations::row_reach(const float* radius, size_t n, gr_uint full, float r_max, float* reach) {
  Impl& m = *impl_;
  if (!m.rows_found || !m.row_reach || n != m.rows_grains) return false;
  *reach = std::numeric_limits<float>::infinity();
  if (n == 0 || full == 0) return true;
  const size_t runs = kBoundsItems;
  Buffer& rb = radius ? m.arrays[kRadius] : m.nb_radius;
  m.upload_once(rb, radius, n * sizeof(float));
  m.stats_part.reserve(m.ctx, runs * sizeof(float), m.largest);
  const int count = static_cast<int>(n), items = static_cast<int>(runs);
  cl_kernel k = m.row_reach;
  arg(k, 0, m.nb_P), arg(k, 1, rb), arg(k, 2, m.nb_offsets);
  arg(k, 3, m.nb_indices);
  arg(k, 4, count), arg(k, 5, items), arg(k, 6, full), arg(k, 7, r_max), arg(k, 8, m.stats_part);
  m.launch(k, runs);
  std::vector<float> part(runs);
  m.download(m.stats_part, part.data(), runs * sizeof(float));
  for (float r : part) *reach = std::min(*reach, r);  // the smallest, in any order the same
  return true;
}

bool Iterations::row_longest(size_t n, size_t* longest) {
  Impl& m = *impl_;
  if (!m.rows_found || !m.row_longest || n != m.rows_grains) return false;
  *longest = 0;
  if (n == 0) return true;
  const size_t runs = kBoundsItems;
  m.stats_part.reserve(m.ctx, runs * sizeof(gr_uint), m.largest);
  const int count = static_cast<int>(n), items = static_cast<int>(runs);
  cl_kernel k = m.row_longest;
  arg(k, 0, m.nb_offsets), arg(k, 1, count), arg(k, 2, items), arg(k, 3, m.stats_part);
  m.launch(k, runs);
  std::vector<gr_uint> part(runs);
  m.download(m.stats_part, part.data(), runs * sizeof(gr_uint));
  for (gr_uint r : part) *longest = std::max<size_t>(*longest, r);
  return true;
}

bool Iterations::holds_prediction(size_t n) const {
  return impl_->p_taken && impl_->p_taken_n == n;
}

bool Iterations::rows_moved(size_t n, float* moved2) {
  Impl& m = *impl_;
  if (!m.rows_moved || n != m.searched_n || m.p_taken != &m.predicted || m.p_taken_n != n)
    return false;
  *moved2 = 0.0f;
  if (n == 0) return true;
  const size_t runs = kBoundsItems;
  m.stats_part.reserve(m.ctx, runs * sizeof(float), m.largest);
  const int count = static_cast<int>(n), items = static_cast<int>(runs);
  cl_kernel k = m.rows_moved;
  arg(k, 0, m.predicted), arg(k, 1, m.nb_P), arg(k, 2, count), arg(k, 3, items);
  arg(k, 4, m.stats_part);
  m.launch(k, runs);
  std::vector<float> part(runs);
  m.download(m.stats_part, part.data(), runs * sizeof(float));
  for (float d : part) *moved2 = std::max(*moved2, d);  // the largest, in any order the same
  return true;
}

void Iterations::fetch_rows_p(float* out, size_t n) {
  Impl& m = *impl_;
  if (n != m.searched_n)
    throw std::logic_error(
        "fetch_rows_p: the device's last search took no positions of these grains");
  if (n) m.download(m.nb_P, out, 3 * n * sizeof(float));
}

bool Iterations::sleep_rows(const float* P, const float* radius, const uint8_t* fast, size_t n,
                            uint32_t* out, const std::vector<gr_uint>* written_there) {
  Impl& m = *impl_;
  if (!m.rows_found || !m.sleep_rows || n != m.rows_grains) return false;
  if (n == 0) return true;
  const size_t f = sizeof(float);
  if (P) m.stats_positions(P, n, written_there);
  m.upload_once(m.arrays[kRadius], radius, n * f);
  m.upload(m.sleep_fast, fast, n);
  m.sleep_out.reserve(m.ctx, n * sizeof(gr_uint), m.largest);
  const int count = static_cast<int>(n);
  cl_kernel k = m.sleep_rows;
  arg(k, 0, m.stats_P), arg(k, 1, m.arrays[kRadius]), arg(k, 2, m.nb_offsets);
  arg(k, 3, m.nb_indices), arg(k, 4, m.sleep_fast), arg(k, 5, count), arg(k, 6, m.sleep_out);
  m.launch(k, n);
  m.download(m.sleep_out, out, n * sizeof(gr_uint));
  return true;
}

}  // namespace grains::opencl
