#include "nodes/grains/opencl/iterations.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "nodes/grains/opencl/cl_program.h"
#include "nodes/grains/opencl/device.h"

namespace grains::opencl {
namespace {

// the kernels take gr_params by value: plain 4-byte fields, the same layout on both sides
static_assert(sizeof(gr_params) % 4 == 0, "gr_params holds 4-byte fields only");

void check(cl_int status, const char* what) {
  if (status != CL_SUCCESS)
    throw std::runtime_error(std::string("OpenCL: ") + what + " failed (" + std::to_string(status) + ")");
}

std::string mib(size_t bytes) {
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
      throw std::runtime_error("use_opencl: the substep needs a device buffer of " + mib(bytes) +
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

// the per-grain arrays of gr_grains, in the kernels' argument order (GR_GRAINS_ARGS)
enum Array {
  kP, kRadius, kInvMass, kMass, kFriction, kRepulsionWeight, kRepulsionStiffness,
  kAttractionWeight, kAttractionStiffness, kNbrOffsets, kNbrIndices, kPairSlip, kPlaneOffsets,
  kPlane, kPlaneSlip, kConOffsets, kConOther, kConPrim, kRestLength, kConstraintWeight,
  kConstraintStiffness, kArrays
};
constexpr cl_uint kScalars = 3;                 // uniform_radius, uniform_inv_mass, nbr_unconstrained
constexpr size_t kGroup = 64;                  // work-items a work-group
constexpr cl_uint kFirstOwn = 1 + kArrays + kScalars;  // after prm, the arrays and the scalars

// one array of gr_grains on the host and how much of it the device reads
struct HostArray {
  const void* host;
  size_t bytes;
};

// g's arrays in Array order (null where g has none)
void grain_arrays(const gr_grains& g, const IterationSizes& size, HostArray* out) {
  const size_t n = size.n, f = sizeof(float), u = sizeof(gr_uint);
  const HostArray a[] = {
      {g.P, 3 * n * f},
      {g.radius, n * f},
      {g.inv_mass, n * f},
      {g.mass, n * f},
      {g.friction, n * f},
      {g.repulsionweight, n * f},
      {g.repulsionstiffness, n * f},
      {g.attractionweight, n * f},
      {g.attractionstiffness, n * f},
      {g.nbr_offsets, (n + 1) * u},
      {g.nbr_indices, size.pair_entries * u},
      {g.pair_slip, 3 * size.pair_entries * f},
      {g.plane_offsets, (n + 1) * u},
      {g.plane, 9 * size.plane_entries * f},
      {g.plane_slip, 3 * size.plane_entries * f},
      {g.con_offsets, (n + 1) * u},
      {g.con_other, 2 * size.prims * u},
      {g.con_prim, 2 * size.prims * u},
      {g.restlength, size.prims * f},
      {g.constraintweight, n * f},
      {g.constraintstiffness, n * f},
  };
  static_assert(sizeof(a) / sizeof(a[0]) == kArrays, "one input per array");
  std::copy(a, a + kArrays, out);
}

}  // namespace

struct Iterations::Impl {
  std::string name;
  cl_context ctx = nullptr;
  cl_command_queue queue = nullptr;
  cl_program program = nullptr;
  // others: gr_k_iterate again, for gauss_seidel's constraints and clumping (its own arguments)
  cl_kernel iterate = nullptr, friction = nullptr, pin = nullptr, others = nullptr, sequential = nullptr;
  Buffer arrays[kArrays];
  Buffer p, next, scratch, pair_sum, collider_sum, collider_dx, friction_dx;
  Buffer target, target_weight, target_stiffness;  // pins
  // gauss_seidel's contacts in parts of whole blocks, each within the largest buffer: part k
  // holds blocks [part_block[k], part_block[k + 1])
  std::vector<Buffer> seq;
  std::vector<size_t> part_block;
  Buffer block_start, colour_blocks;
  // the most bytes one buffer may hold: the device's CL_DEVICE_MAX_MEM_ALLOC_SIZE, or less
  // when GRAINS_OPENCL_MAX_BUFFER_MIB says so
  size_t largest = 0;

  ~Impl() {
    for (Buffer& b : arrays) b.release();
    for (Buffer* b : {&p, &next, &scratch, &pair_sum, &collider_sum, &collider_dx, &friction_dx,
                      &target, &target_weight, &target_stiffness, &block_start, &colour_blocks})
      b->release();
    for (Buffer& b : seq) b.release();
    for (cl_kernel k : {iterate, friction, pin, others, sequential})
      if (k) clReleaseKernel(k);
    if (program) clReleaseProgram(program);
    if (queue) clReleaseCommandQueue(queue);
    if (ctx) clReleaseContext(ctx);
  }

  // copies `bytes` of host memory to b (grown as needed); a null host array leaves b unset
  void upload(Buffer& b, const void* host, size_t bytes, size_t device_bytes = 0) {
    if (!host) return;
    b.reserve(ctx, std::max(bytes, device_bytes), largest);
    if (bytes > 0) check(clEnqueueWriteBuffer(queue, b.mem, CL_FALSE, 0, bytes, host, 0, nullptr, nullptr),
                         "clEnqueueWriteBuffer");
  }
  void download(Buffer& b, void* host, size_t bytes) {
    if (!host || bytes == 0) return;
    check(clEnqueueReadBuffer(queue, b.mem, CL_TRUE, 0, bytes, host, 0, nullptr, nullptr),
          "clEnqueueReadBuffer");
  }

  // g's arrays (grain_arrays, into a) to `arrays` and the positions p to `p`, once a call;
  // `next` made room for the passes that swap with p
  void upload_grains(const gr_grains& g, const IterationSizes& size, const float* positions, HostArray* a) {
    grain_arrays(g, size, a);
    for (int k = 0; k < kArrays; ++k)
      // positions: one float past the last grain, as the contact loop's block loads read
      upload(arrays[k], a[k].host, a[k].bytes, k == kP ? a[k].bytes + sizeof(float) : 0);
    const size_t bytes = (3 * size.n + 1) * sizeof(float);
    upload(p, positions, bytes);
    next.reserve(ctx, bytes, largest);
  }
  // kernel k's first arguments: prm, the arrays `a` holds (null where it has none) and g's scalars
  void set_grains(cl_kernel k, const gr_params& prm, const gr_grains& g, const HostArray* a);
  // the pins' arguments (g.targetP and its arrays uploaded), and one pin projection of x
  void set_pins(const gr_grains& g, const gr_params& prm, size_t n);
  void project_pins(Buffer* x, size_t global);
};

namespace {

// a buffer argument, or null for a missing array (OpenCL 1.2: a null arg_value is a null pointer)
void set_buffer(cl_kernel k, cl_uint index, const Buffer* b) {
  cl_mem m = b ? b->mem : nullptr;
  check(clSetKernelArg(k, index, sizeof(cl_mem), b ? &m : nullptr), "clSetKernelArg");
}

}  // namespace

Iterations::Iterations() : impl_(std::make_unique<Impl>()) {
  DeviceChoice choice;
  std::string problem;
  if (!chosen_device(&choice, &problem)) throw std::runtime_error("use_opencl: " + problem);
  cl_device_id d = device_id(choice.platform, choice.device, &problem);
  if (!d) throw std::runtime_error("use_opencl: " + problem);
  {
    const std::vector<Platform> list = platforms(&problem);
    impl_->name = list[choice.platform].devices[choice.device].name + " (platform " +
                  std::to_string(choice.platform) + ", " + list[choice.platform].name + ")";
  }
  cl_ulong largest = 0;
  check(clGetDeviceInfo(d, CL_DEVICE_MAX_MEM_ALLOC_SIZE, sizeof largest, &largest, nullptr),
        "clGetDeviceInfo(CL_DEVICE_MAX_MEM_ALLOC_SIZE)");
  impl_->largest = static_cast<size_t>(largest);
  uint64_t cap = 0;
  if (!buffer_cap(&cap, &problem)) throw std::runtime_error("use_opencl: " + problem);
  if (cap > 0) impl_->largest = std::min(impl_->largest, static_cast<size_t>(cap));
  cl_int status = CL_SUCCESS;
  impl_->ctx = clCreateContext(nullptr, 1, &d, nullptr, nullptr, &status);
  check(status, "clCreateContext");
  impl_->queue = clCreateCommandQueue(impl_->ctx, d, 0, &status);
  check(status, "clCreateCommandQueue");
  std::string log;
  impl_->program = build_program(impl_->ctx, d, &log);
  if (!impl_->program)
    throw std::runtime_error("use_opencl: the grains kernels do not build on " + impl_->name + ": " + log);
  impl_->iterate = clCreateKernel(impl_->program, "gr_k_iterate", &status);
  check(status, "clCreateKernel(gr_k_iterate)");
  impl_->friction = clCreateKernel(impl_->program, "gr_k_friction", &status);
  check(status, "clCreateKernel(gr_k_friction)");
  impl_->pin = clCreateKernel(impl_->program, "gr_k_pin", &status);
  check(status, "clCreateKernel(gr_k_pin)");
  impl_->others = clCreateKernel(impl_->program, "gr_k_iterate", &status);
  check(status, "clCreateKernel(gr_k_iterate)");
  impl_->sequential = clCreateKernel(impl_->program, "gr_k_sequential", &status);
  check(status, "clCreateKernel(gr_k_sequential)");
}

Iterations::~Iterations() = default;

const std::string& Iterations::device_name() const { return impl_->name; }

void Iterations::Impl::set_grains(cl_kernel k, const gr_params& prm, const gr_grains& g, const HostArray* a) {
  check(clSetKernelArg(k, 0, sizeof(gr_params), &prm), "clSetKernelArg(prm)");
  for (int e = 0; e < kArrays; ++e) set_buffer(k, 1 + e, a[e].host ? &arrays[e] : nullptr);
  const float ur = g.uniform_radius, uw = g.uniform_inv_mass;
  const int unconstrained = g.nbr_unconstrained;
  check(clSetKernelArg(k, 1 + kArrays, sizeof(float), &ur), "clSetKernelArg");
  check(clSetKernelArg(k, 2 + kArrays, sizeof(float), &uw), "clSetKernelArg");
  check(clSetKernelArg(k, 3 + kArrays, sizeof(int), &unconstrained), "clSetKernelArg");
}

void Iterations::Impl::set_pins(const gr_grains& g, const gr_params& prm, size_t n) {
  const size_t f = sizeof(float);
  upload(target, g.targetP, 3 * n * f);
  upload(target_weight, g.targetweight, n * f);
  upload(target_stiffness, g.targetstiffness, n * f);
  const int count = static_cast<int>(n);
  check(clSetKernelArg(pin, 0, sizeof(gr_params), &prm), "clSetKernelArg(prm)");
  set_buffer(pin, 1, &target);
  set_buffer(pin, 2, g.targetweight ? &target_weight : nullptr);
  set_buffer(pin, 3, &target_stiffness);
  check(clSetKernelArg(pin, 5, sizeof(int), &count), "clSetKernelArg");
}

void Iterations::Impl::project_pins(Buffer* x, size_t global) {
  const size_t local = kGroup;
  set_buffer(pin, 4, x);
  check(clEnqueueNDRangeKernel(queue, pin, 1, nullptr, &global, &local, 0, nullptr, nullptr),
        "clEnqueueNDRangeKernel");
}

void Iterations::run(const gr_grains& g, const gr_params& prm, const IterationSizes& size, float* p,
                     const gr_normal_sums& acc, int iterations, bool friction_pass,
                     bool accurate_friction) {
  Impl& m = *impl_;
  const size_t n = size.n;
  if (n == 0) return;
  const size_t f = sizeof(float), u = sizeof(gr_uint);
  HostArray inputs[kArrays];
  m.upload_grains(g, size, p, inputs);
  const bool pairs = acc.pair && g.nbr_offsets;
  if (pairs) m.scratch.reserve(m.ctx, n * size.row_length * f, m.largest);
  m.upload(m.pair_sum, acc.pair, size.pair_entries * u);
  m.upload(m.collider_sum, acc.collider, size.plane_entries * f);
  m.upload(m.collider_dx, acc.collider_dx, 3 * GR_MAX_PLANES * n * f);
  m.upload(m.friction_dx, acc.friction_dx, 3 * n * f);

  for (cl_kernel k : {m.iterate, m.friction}) m.set_grains(k, prm, g, inputs);
  const int count = static_cast<int>(n);
  const gr_uint row_length = static_cast<gr_uint>(size.row_length);
  // iterate: p, next, scratch, row_length, pair_sum, collider_sum, collider_dx, friction_dx, n
  set_buffer(m.iterate, kFirstOwn + 2, pairs ? &m.scratch : nullptr);
  check(clSetKernelArg(m.iterate, kFirstOwn + 3, sizeof(gr_uint), &row_length), "clSetKernelArg");
  set_buffer(m.iterate, kFirstOwn + 4, acc.pair ? &m.pair_sum : nullptr);
  set_buffer(m.iterate, kFirstOwn + 5, acc.collider ? &m.collider_sum : nullptr);
  set_buffer(m.iterate, kFirstOwn + 6, acc.collider_dx ? &m.collider_dx : nullptr);
  set_buffer(m.iterate, kFirstOwn + 7, acc.friction_dx ? &m.friction_dx : nullptr);
  check(clSetKernelArg(m.iterate, kFirstOwn + 8, sizeof(int), &count), "clSetKernelArg");
  // friction: p, next, pair_sum, collider_sum, collider_dx, friction_dx, n
  set_buffer(m.friction, kFirstOwn + 2, acc.pair ? &m.pair_sum : nullptr);
  set_buffer(m.friction, kFirstOwn + 3, acc.collider ? &m.collider_sum : nullptr);
  set_buffer(m.friction, kFirstOwn + 4, acc.collider_dx ? &m.collider_dx : nullptr);
  set_buffer(m.friction, kFirstOwn + 5, acc.friction_dx ? &m.friction_dx : nullptr);
  check(clSetKernelArg(m.friction, kFirstOwn + 6, sizeof(int), &count), "clSetKernelArg");

  // p and next swap after every pass, as the CPU loop swaps its iterates
  Buffer* from = &m.p;
  Buffer* to = &m.next;
  // one work-group size whatever n is: a compiler that specialises kernels for it (PoCL) then
  // builds each kernel once, not once per grain count
  const size_t local = kGroup, global = (n + kGroup - 1) / kGroup * kGroup;
  auto pass = [&](cl_kernel k) {
    set_buffer(k, kFirstOwn, from);
    set_buffer(k, kFirstOwn + 1, to);
    check(clEnqueueNDRangeKernel(m.queue, k, 1, nullptr, &global, &local, 0, nullptr, nullptr),
          "clEnqueueNDRangeKernel");
    std::swap(from, to);
  };
  // pins (g.targetstiffness set): their own group after each iteration, in place, on `from`
  const bool pins = g.targetP && g.targetstiffness;
  if (pins) m.set_pins(g, prm, n);
  for (int it = 0; it < iterations; ++it) {
    pass(m.iterate);
    if (friction_pass && accurate_friction) pass(m.friction);
    if (pins) m.project_pins(from, global);
  }
  if (friction_pass && !accurate_friction) pass(m.friction);

  m.download(*from, p, 3 * n * f);
  m.download(m.pair_sum, acc.pair, size.pair_entries * u);
  m.download(m.collider_sum, acc.collider, size.plane_entries * f);
  m.download(m.collider_dx, acc.collider_dx, 3 * GR_MAX_PLANES * n * f);
  m.download(m.friction_dx, acc.friction_dx, 3 * n * f);
}

void Iterations::run_sequential(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                                float* p, const SequentialContacts& s, int iterations) {
  Impl& m = *impl_;
  const size_t n = size.n;
  if (n == 0) return;
  const size_t f = sizeof(float), u = sizeof(gr_uint);
  HostArray inputs[kArrays];
  m.upload_grains(g, size, p, inputs);
  // the contacts in parts of whole blocks (Impl::seq): a million grains' take about 0.5 GB, more
  // than some devices' largest buffer (PoCL: 4 GiB) at ten million
  const size_t per = sizeof(gr_seq_contact);
  m.part_block.assign(1, 0);
  for (size_t b = 0; b < s.blocks; ++b)
    if (b > m.part_block.back() && (s.block_start[b + 1] - s.block_start[m.part_block.back()]) * per > m.largest)
      m.part_block.push_back(b);
  m.part_block.push_back(s.blocks);
  const size_t parts = m.part_block.size() - 1;
  for (size_t k = parts; k < m.seq.size(); ++k) m.seq[k].release();
  m.seq.resize(parts);
  auto part_first = [&](size_t k) { return s.block_start[m.part_block[k]]; };
  auto part_count = [&](size_t k) { return s.block_start[m.part_block[k + 1]] - part_first(k); };
  for (size_t k = 0; k < parts; ++k) m.upload(m.seq[k], s.contacts + part_first(k), part_count(k) * per);
  m.upload(m.block_start, s.block_start, (s.blocks + 1) * u);
  m.upload(m.colour_blocks, s.colour_blocks, s.blocks * u);

  const size_t local = kGroup, global = (n + kGroup - 1) / kGroup * kGroup;
  Buffer* from = &m.p;
  Buffer* to = &m.next;
  // the others' Jacobi group: gr_k_iterate with their arrays and no sums
  if (s.others) {
    HostArray theirs[kArrays];
    grain_arrays(*s.others, size, theirs);
    m.set_grains(m.others, *s.others_prm, *s.others, theirs);
    const int count = static_cast<int>(n);
    const gr_uint none = 0;
    for (cl_uint a = kFirstOwn + 2; a <= kFirstOwn + 7; ++a)
      if (a == kFirstOwn + 3) check(clSetKernelArg(m.others, a, sizeof(gr_uint), &none), "clSetKernelArg");
      else set_buffer(m.others, a, nullptr);
    check(clSetKernelArg(m.others, kFirstOwn + 8, sizeof(int), &count), "clSetKernelArg");
  }
  // the contacts: p, seq, block_start, blocks, first, count, relax, base (seq, first, count and
  // base by colour and part)
  m.set_grains(m.sequential, prm, g, inputs);
  set_buffer(m.sequential, kFirstOwn + 2, &m.block_start);
  set_buffer(m.sequential, kFirstOwn + 3, &m.colour_blocks);
  check(clSetKernelArg(m.sequential, kFirstOwn + 6, sizeof(float), &s.relax), "clSetKernelArg");
  const bool pins = g.targetP && g.targetstiffness;
  if (pins) m.set_pins(g, prm, n);
  for (int it = 0; it < iterations; ++it) {
    if (s.others) {
      set_buffer(m.others, kFirstOwn, from);
      set_buffer(m.others, kFirstOwn + 1, to);
      check(clEnqueueNDRangeKernel(m.queue, m.others, 1, nullptr, &global, &local, 0, nullptr, nullptr),
            "clEnqueueNDRangeKernel");
      std::swap(from, to);
    }
    set_buffer(m.sequential, kFirstOwn, from);
    for (size_t c = 0; c < s.colours && s.count > 0; ++c)
      for (size_t k = 0; k < parts; ++k) {
        // the colour's blocks (ascending) that lie in part k; blocks of one colour touch no
        // common grain, so sweeping them part by part gives what one launch would
        const gr_uint* from_block = s.colour_blocks + s.colour_start[c];
        const gr_uint* to_block = s.colour_blocks + s.colour_start[c + 1];
        const gr_uint* lo = std::lower_bound(from_block, to_block, static_cast<gr_uint>(m.part_block[k]));
        const gr_uint* hi = std::lower_bound(lo, to_block, static_cast<gr_uint>(m.part_block[k + 1]));
        if (lo == hi) continue;
        const int first = static_cast<int>(lo - s.colour_blocks);
        const int count = static_cast<int>(hi - lo);
        const gr_uint base = part_first(k);
        set_buffer(m.sequential, kFirstOwn + 1, &m.seq[k]);
        check(clSetKernelArg(m.sequential, kFirstOwn + 4, sizeof(int), &first), "clSetKernelArg");
        check(clSetKernelArg(m.sequential, kFirstOwn + 5, sizeof(int), &count), "clSetKernelArg");
        check(clSetKernelArg(m.sequential, kFirstOwn + 7, sizeof(gr_uint), &base), "clSetKernelArg");
        // a work-item a block (a block is 1,024 grains: a colour has few), in whole groups
        const size_t items = (static_cast<size_t>(count) + kGroup - 1) / kGroup * kGroup;
        check(clEnqueueNDRangeKernel(m.queue, m.sequential, 1, nullptr, &items, &local, 0, nullptr, nullptr),
              "clEnqueueNDRangeKernel");
      }
    if (pins) m.project_pins(from, global);
  }
  m.download(*from, p, 3 * n * f);
  for (size_t k = 0; k < parts; ++k) m.download(m.seq[k], s.contacts + part_first(k), part_count(k) * per);
}

}  // namespace grains::opencl
