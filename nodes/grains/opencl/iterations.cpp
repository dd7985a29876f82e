#include "nodes/grains/opencl/iterations.h"

#include <algorithm>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "nodes/grains/kernels/shapes.h"
#include "nodes/grains/opencl/device.h"
#include "nodes/grains/opencl/device_state.h"

namespace grains::opencl {

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
  // a block's waves shared among work-items: on a CPU one work-item sweeps its block (a core
  // gains nothing from splitting a wave), a GPU's many lanes take a wave's contacts at once
  uint64_t items = 0;
  if (!sweep_items(&items, &problem)) throw std::runtime_error("use_opencl: " + problem);
  if (items == 0) {
    cl_device_type type = 0;
    check(clGetDeviceInfo(d, CL_DEVICE_TYPE, sizeof type, &type, nullptr),
          "clGetDeviceInfo(CL_DEVICE_TYPE)");
    items = (type & CL_DEVICE_TYPE_CPU) ? 1 : 64;
  }
  impl_->sweep_items = static_cast<size_t>(items);
  bool host = false;
  if (!host_contacts(&host, &problem)) throw std::runtime_error("use_opencl: " + problem);
  impl_->builds_contacts = !host;
  if (!host_sleep(&impl_->host_sleep, &problem)) throw std::runtime_error("use_opencl: " + problem);
  impl_->device = d;
  cl_int status = CL_SUCCESS;
  impl_->ctx = clCreateContext(nullptr, 1, &d, nullptr, nullptr, &status);
  check(status, "clCreateContext");
  impl_->queue = clCreateCommandQueue(impl_->ctx, d, 0, &status);
  check(status, "clCreateCommandQueue");
  std::string log;
  impl_->program = build_program(impl_->ctx, d, &log);
  if (!impl_->program)
    throw std::runtime_error("use_opencl: the grains kernels do not build on " + impl_->name +
                             ": " + log);
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

void Iterations::begin_substep() {
  impl_->once.clear();
  impl_->p_taken = nullptr;
  impl_->carry_from_n = 0;
  impl_->run_out_n = 0;
  impl_->start_kept = 0;
  impl_->table_made = false;
}

bool Iterations::carry_start(const float* P, const float* v, size_t n, const float origin[3],
                             const std::vector<gr_uint>& changed,
                             const std::vector<gr_uint>* from) {
  Impl& m = *impl_;
  if (n == 0 || m.carry_n == 0 || (from ? from->size() != n : m.carry_n != n) ||
      (v && m.carry_v_n != m.carry_n))
    return false;
  const size_t f = sizeof(float);
  Buffer& start = m.arrays[kP];
  start.reserve(m.ctx, (3 * n + 1) * f, m.largest);  // and the zero past the last grain
  if (v) m.velocity.reserve(m.ctx, 3 * n * f, m.largest);
  // end_P, origin, P, end_v, v, n
  cl_kernel k = m.kernel(m.carry, "gr_k_carry");
  const int count = static_cast<int>(n);
  arg(k, 0, m.carry_P), arg(k, 1, origin[0]), arg(k, 2, origin[1]), arg(k, 3, origin[2]);
  arg(k, 4, start), arg(k, 7, count);
  set_buffer(k, 5, v ? &m.end_v : nullptr);
  set_buffer(k, 6, v ? &m.velocity : nullptr);
  if (from) m.upload(m.carry_from, from->data(), n * sizeof(gr_uint));
  m.carry_from_n = from ? n : 0;
  set_buffer(k, 8, from ? &m.carry_from : nullptr);
  m.launch(k, n);
  m.patch(start, P, changed, false, 0);
  if (v) m.patch(m.velocity, v, changed, true, 1);
  m.copied_once(start, P, 3 * n * f);
  if (v) m.copied_once(m.velocity, v, 3 * n * f);
  return true;
}

bool Iterations::end_bounds(size_t n, float lo[3], float hi[3], bool* finite) {
  Impl& m = *impl_;
  if (n == 0 || m.carry_n != n || m.carry_v_n != n) return false;
  // a work-item a 64 grains, in whole work-groups, at most 16 of them: 28 bytes each
  const size_t items = std::min(16 * kGroup, ((n + 63) / 64 + kGroup - 1) / kGroup * kGroup);
  m.end_part.reserve(m.ctx, 7 * items * sizeof(float), m.largest);
  cl_kernel k = m.kernel(m.end_bounds, "gr_k_end_bounds");
  const int count = static_cast<int>(n);
  arg(k, 0, m.carry_P), arg(k, 1, m.end_v), arg(k, 2, count), arg(k, 3, m.end_part);
  m.launch(k, items);
  std::vector<float> part(7 * items);
  m.download(m.end_part, part.data(), part.size() * sizeof(float));
  const float inf = std::numeric_limits<float>::infinity();
  *finite = true;
  for (int a = 0; a < 3; ++a) lo[a] = inf, hi[a] = -inf;
  // the smallest and the largest, in any order the same
  for (size_t w = 0; w < items; ++w) {
    for (int a = 0; a < 3; ++a)
      lo[a] = std::min(lo[a], part[7 * w + a]), hi[a] = std::max(hi[a], part[7 * w + 3 + a]);
    if (part[7 * w + 6] != 0.0f) *finite = false;
  }
  return true;
}

bool Iterations::motion(size_t n, bool has_force, bool force_uniform, bool awake, double step,
                        double fps, double* worst, double* fall) {
  Impl& m = *impl_;
  m.open_neighbours();  // the kernel sits beside the rows' (cl_khr_fp64)
  if (n == 0 || m.carry_v_n != n || !m.bounds || (awake && m.asleep_n != n)) return false;
  // the work-items of end_bounds
  const size_t items = std::min(16 * kGroup, ((n + 63) / 64 + kGroup - 1) / kGroup * kGroup);
  m.motion_part.reserve(m.ctx, 2 * items * sizeof(double), m.largest);
  cl_kernel k = m.kernel(m.motion, "gr_k_motion");
  const int count = static_cast<int>(n), runs = static_cast<int>(items),
            uniform = force_uniform ? 1 : 0;
  arg(k, 0, m.end_v), set_buffer(k, 1, has_force ? &m.force : nullptr), arg(k, 2, uniform);
  arg(k, 3, awake ? m.sleep_mass : m.arrays[kMass]), arg(k, 4, m.arrays[kRadius]);
  arg(k, 5, step), arg(k, 6, fps), arg(k, 7, count), arg(k, 8, runs), arg(k, 9, m.motion_part);
  m.launch(k, items);
  std::vector<double> part(2 * items);
  m.download(m.motion_part, part.data(), part.size() * sizeof(double));
  for (size_t w = 0; w < items; ++w) {  // the largest, in any order the same
    if (*worst < part[2 * w]) *worst = part[2 * w];
    if (*fall < part[2 * w + 1]) *fall = part[2 * w + 1];
  }
  return true;
}

bool Iterations::fetch_end(float* P, float* v, size_t n) {
  Impl& m = *impl_;
  if (m.carry_n != n || (v && m.carry_v_n != n)) return false;
  m.download(m.carry_P, P, 3 * n * sizeof(float));
  m.download(m.end_v, v, 3 * n * sizeof(float));
  return true;
}

void Iterations::predict(const gr_grains& g, const gr_params& prm, size_t n, const float* force,
                         bool force_uniform) {
  Impl& m = *impl_;
  if (n == 0) return;
  const size_t f = sizeof(float);
  IterationSizes size;
  size.n = n;
  HostArray inputs[kArrays];
  grain_arrays(g, size, inputs);
  // what the solve and the end read too, sent once a substep (carry_start may have made the
  // start and the velocities here)
  m.upload_once(m.arrays[kP], g.P, 3 * n * f, (3 * n + 1) * f);
  m.upload_once(m.arrays[kMass], g.mass, n * f);
  m.upload_once(m.velocity, g.v, 3 * n * f);
  const int uniform = force_uniform ? 1 : 0;
  m.upload_once(m.force, force, (uniform ? 3 : 3 * n) * f);
  m.predicted.reserve(m.ctx, (3 * n + 1) * f, m.largest);
  // prm, grains, v, force, force_uniform, p, n
  cl_kernel k = m.kernel(m.predict, "gr_k_predict");
  m.set_grains(k, prm, g, inputs);
  const int count = static_cast<int>(n);
  set_buffer(k, kFirstOwn, &m.velocity);
  set_buffer(k, kFirstOwn + 1, force ? &m.force : nullptr);
  arg(k, kFirstOwn + 2, uniform);
  set_buffer(k, kFirstOwn + 3, &m.predicted);
  arg(k, kFirstOwn + 4, count);
  m.launch(k, n);
  m.p_taken = &m.predicted;
  m.p_taken_n = n;
}

Traffic Iterations::traffic() const {
  return impl_->traffic;
}

const std::string& Iterations::device_name() const {
  return impl_->name;
}

bool Iterations::shares_blocks() const {
  return impl_->sweep_items > 1;
}

bool Iterations::shapes_there() {
  impl_->open_neighbours();  // the program has gr_k_shapes where it has the grid's kernels
  return impl_->bounds != nullptr;
}

bool Iterations::meshes_there() {
  return shapes_there();  // (both need double precision, as the grid's kernels)
}

bool Iterations::builds_contacts() const {
  return impl_->builds_contacts;
}

void Iterations::Impl::upload_grains(const gr_grains& g, const IterationSizes& size,
                                     const float* positions, HostArray* a, bool rows_only) {
  run_out_n = 0;  // p and next are rewritten
  grain_arrays(g, size, a);
  stand_in_rows(size, a);
  // the rows the device's search left where they are (size.rows_there): copied there
  const bool rows_there = size.rows_there && rows_found && rows_grains == size.n;
  // positions: one float past the last grain, as the contact loop's block loads read
  for (int k = 0; k < kArrays; ++k) {
    if (!((!rows_only || k == kNbrOffsets || k == kNbrIndices) &&
          !(size.planes_there && (k == kPlaneOffsets || k == kPlane))))
      continue;
    if (k == kPairSlip && size.slips_there) continue;  // the device made them, or they went
    if (k == kPlaneSlip && size.plane_slips_there) continue;  // the device made them
    if (rows_there && (k == kNbrOffsets || k == kNbrIndices)) {
      copy_once(arrays[k], k == kNbrOffsets ? nb_offsets : nb_indices, a[k].host, a[k].bytes);
      continue;
    }
    const size_t device_bytes = k == kP ? a[k].bytes + sizeof(float) : 0;
    // the rows and the planes (and their slips) may be found again within the substep
    const bool same_all_substep = k != kNbrOffsets && k != kNbrIndices && k != kPairSlip &&
                                  k != kPlaneOffsets && k != kPlane && k != kPlaneSlip;
    if (same_all_substep)
      upload_once(arrays[k], a[k].host, a[k].bytes, device_bytes);
    else
      upload(arrays[k], a[k].host, a[k].bytes, device_bytes);
  }
  const size_t bytes = (3 * size.n + 1) * sizeof(float);
  upload(p, positions, bytes);
  next.reserve(ctx, bytes, largest);
}

void Iterations::Impl::stand_in_rows(const IterationSizes& size, HostArray* a) const {
  if (size.rows_there && rows_found && rows_grains == size.n && a[kNbrOffsets].host &&
      !a[kNbrIndices].host)
    a[kNbrIndices].host = &nb_indices;
}

void Iterations::Impl::set_grains(cl_kernel k, const gr_params& prm, const gr_grains& g,
                                  const HostArray* a) {
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
  upload_once(target, g.targetP, 3 * n * f);
  upload_once(target_weight, g.targetweight, n * f);
  upload_once(target_stiffness, g.targetstiffness, n * f);
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

void Iterations::Impl::set_shapes(const ShapeArrays& sh, const gr_params& prm, const gr_grains& g,
                                  const HostArray* inputs, Buffer* normal, size_t n) {
  kernel(shapes, "gr_k_shapes");
  const size_t f = sizeof(float), u = sizeof(gr_uint);
  if (sh.generation == 0 || sh.generation != shape_generation || shape_grains != n) {
    upload(shape_offsets, sh.offsets, (sh.components + 1) * u);
    upload(shape_members, sh.members, sh.offsets[sh.components] * u);
    upload(shape_rest, sh.rest, 3 * n * f);
    shape_generation = sh.generation;
    shape_grains = n;
  }
  upload_once(shape_mass, sh.mass, n * f);
  // prm, g's arrays, p (project_shapes), the components' arrays, the normal sums, their count
  set_grains(shapes, prm, g, inputs);
  set_buffer(shapes, kFirstOwn + 1, &shape_offsets);
  set_buffer(shapes, kFirstOwn + 2, &shape_members);
  set_buffer(shapes, kFirstOwn + 3, &shape_rest);
  set_buffer(shapes, kFirstOwn + 4, &shape_mass);
  set_buffer(shapes, kFirstOwn + 5, normal);
  arg(shapes, kFirstOwn + 6, static_cast<int>(sh.components));
}

void Iterations::Impl::project_shapes(Buffer* x, size_t components) {
  static_assert(kGroup == GR_SHAPE_LANES, "a component's lanes are one work-group");
  const size_t local = kGroup, items = components * kGroup;  // a work-group a component
  set_buffer(shapes, kFirstOwn, x);
  check(clEnqueueNDRangeKernel(queue, shapes, 1, nullptr, &items, &local, 0, nullptr, nullptr),
        "clEnqueueNDRangeKernel");
}

void Iterations::run(const gr_grains& g_in, const gr_params& prm, const IterationSizes& size_in,
                     float* p, const gr_normal_sums& acc_in, int iterations, bool friction_pass,
                     bool accurate_friction, const JacobiSolve& w) {
  Impl& m = *impl_;
  const size_t n = size_in.n;
  if (n == 0) return;
  // (a rebuild during the iterations rewrites them: JacobiSolve::rebuild)
  gr_grains g = g_in;
  IterationSizes size = size_in;
  gr_normal_sums acc = acc_in;
  const size_t f = sizeof(float), u = sizeof(gr_uint);
  HostArray inputs[kArrays];
  const bool p_there = w.p_there && m.p_taken && m.p_taken_n == n;
  m.upload_grains(g, size, p_there ? nullptr : p, inputs);
  if (p_there) m.copy_positions(m.p, *m.p_taken, n);
  if (size.sums_there)
    m.pair_sum.reserve(m.ctx, size.pair_entries * u, m.largest);
  else
    m.upload(m.pair_sum, acc.pair, size.pair_entries * u);
  m.upload(m.collider_sum, acc.collider, size.plane_entries * f);
  m.upload(m.collider_dx, acc.collider_dx, 3 * GR_MAX_PLANES * n * f);
  if (size.friction_there)
    m.friction_dx.reserve(m.ctx, 3 * n * f, m.largest);
  else
    m.upload(m.friction_dx, acc.friction_dx, 3 * n * f);

  const int count = static_cast<int>(n);
  // the passes' arguments but their positions (set again after a rebuild)
  auto bind = [&] {
    const bool pairs = acc.pair && g.nbr_offsets;
    if (pairs) m.scratch.reserve(m.ctx, n * size.row_length * f, m.largest);
    for (cl_kernel k : {m.iterate, m.friction}) m.set_grains(k, prm, g, inputs);
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
  };
  bind();

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
  // the shapes, in place on `from` after each iteration and each friction pass, their normal
  // sums the iterations' collider sums
  const ShapeArrays* sh = w.shapes && w.shapes->components > 0 ? w.shapes : nullptr;
  if (sh) m.set_shapes(*sh, prm, g, inputs, acc.collider ? &m.collider_sum : nullptr, n);
  // Chebyshev: the iterate before the last in `before` (x_{-1} = x_0: the first steps are plain
  // Jacobi), which the step makes the next; the three buffers then turn
  const bool chebyshev = w.chebyshev_rho > 0.0f;
  Buffer* before = &m.before;
  float omega = 1.0f;
  if (chebyshev) {
    m.copy_positions(m.before, *from, n);
    const int items = static_cast<int>(n);
    cl_kernel k = m.kernel(m.chebyshev, "gr_k_chebyshev");
    check(clSetKernelArg(k, 3, sizeof(int), &items), "clSetKernelArg");
  }
  for (int it = 0; it < iterations; ++it) {
    if (it > 0 && w.rebuild) {
      // the searches take the iterate where it is; the prediction is not there after them
      m.p_taken = from, m.p_taken_n = n;
      m.rebuilding = true;
      w.rebuild(&g, &size, &acc);
      m.rebuilding = false;
      m.p_taken = nullptr, m.p_taken_n = 0;
      m.upload_grains(g, size, nullptr, inputs, true);  // the rows where the passes read them
      bind();
      if (sh) m.set_shapes(*sh, prm, g, inputs, acc.collider ? &m.collider_sum : nullptr, n);
    }
    if (chebyshev) {
      omega = gr_chebyshev_omega(it, w.chebyshev_rho, omega);
      Buffer* was = from;
      pass(m.iterate);  // into to: x^
      if (omega != 1.0f) {
        set_buffer(m.chebyshev, 0, from);
        set_buffer(m.chebyshev, 1, before);
        check(clSetKernelArg(m.chebyshev, 2, sizeof(float), &omega), "clSetKernelArg");
        check(clEnqueueNDRangeKernel(m.queue, m.chebyshev, 1, nullptr, &global, &local, 0, nullptr,
                                     nullptr),
              "clEnqueueNDRangeKernel");
        to = from, from = before;
      } else {
        to = before;
      }
      before = was;
    } else {
      pass(m.iterate);
    }
    if (sh) m.project_shapes(from, sh->components);
    if (friction_pass && accurate_friction) {
      pass(m.friction);
      if (sh) m.project_shapes(from, sh->components);
    }
    if (pins) m.project_pins(from, global);
  }
  if (friction_pass && !accurate_friction) {
    pass(m.friction);
    if (sh) m.project_shapes(from, sh->components);
  }

  if (w.finish)
    m.finish_substep(g, prm, inputs, from, *w.finish, false,
                     m.start_kept == n ? &m.start : &m.arrays[kP], n);
  else
    m.download(*from, p, 3 * n * f);
  m.run_out = from, m.run_out_n = n;
  if (!size.sums_stay) m.download(m.pair_sum, acc.pair, size.pair_entries * u);
  // (save_pair_history: the device's are the sums, whether or not they came back)
  if (acc.pair) m.copied_once(m.pair_sum, acc.pair, size.pair_entries * u);
  if (!size.collider_sums_stay) m.download(m.collider_sum, acc.collider, size.plane_entries * f);
  if (acc.collider) m.copied_once(m.collider_sum, acc.collider, size.plane_entries * f);
  // (the impact data made there read them there)
  if (!(w.finish && w.finish->impact_collider))
    m.download(m.collider_dx, acc.collider_dx, 3 * GR_MAX_PLANES * n * f);
}

void Iterations::Impl::upload_contacts(const SequentialContacts& s) {
  // the contacts in parts of whole blocks (Impl::seq): a million grains' take about 0.5 GB, more
  // than some devices' largest buffer (PoCL: 4 GiB) at ten million
  const size_t per = sizeof(gr_seq_contact);
  part_block.assign(1, 0);
  for (size_t b = 0; b < s.blocks; ++b)
    if (b > part_block.back() &&
        (s.block_start[b + 1] - s.block_start[part_block.back()]) * per > largest)
      part_block.push_back(b);
  part_block.push_back(s.blocks);
  const size_t parts = part_block.size() - 1;
  for (size_t k = parts; k < seq.size(); ++k) seq[k].release();
  seq.resize(parts);
  for (size_t k = 0; k < parts; ++k) {
    const size_t first = s.block_start[part_block[k]],
                 count = s.block_start[part_block[k + 1]] - first;
    upload(seq[k], s.contacts + first, count * per);
  }
  held = s.count;
  held_whole = parts == 1;
  upload_blocks(s);
}

void Iterations::Impl::upload_blocks(const SequentialContacts& s) {
  const size_t u = sizeof(gr_uint);
  upload(block_wave, s.block_wave, (s.blocks + 1) * u);
  upload(wave_start, s.wave_start, (s.waves + 1) * u);
  upload(colour_blocks, s.colour_blocks, s.blocks * u);
}

void Iterations::Impl::sweep_colour(cl_kernel k, PartArgs at, const SequentialContacts& s,
                                    size_t c) {
  // a work-group a block: a device spreads work-groups over its compute units (PoCL runs a
  // work-group on one core), and a colour has few blocks; its work-items share each wave
  size_t local = 0;
  for (const auto& [kernel, limit] : group_limit)
    if (kernel == k) local = limit;
  if (local == 0) {
    size_t limit = 1;
    check(clGetKernelWorkGroupInfo(k, device, CL_KERNEL_WORK_GROUP_SIZE, sizeof limit, &limit,
                                   nullptr),
          "clGetKernelWorkGroupInfo");
    local = std::max<size_t>(1, std::min(sweep_items, limit));
    group_limit.emplace_back(k, local);
  }
  if (at.local_floats != PartArgs::kNoArg)
    check(clSetKernelArg(k, at.local_floats, local * sizeof(float), nullptr), "clSetKernelArg");
  for (size_t part = 0; part + 1 < part_block.size(); ++part) {
    // the colour's blocks (ascending) that lie in this part; blocks of one colour touch no
    // common grain, so sweeping them part by part gives what one launch would
    const gr_uint* from_block = s.colour_blocks + s.colour_start[c];
    const gr_uint* to_block = s.colour_blocks + s.colour_start[c + 1];
    const gr_uint* lo =
        std::lower_bound(from_block, to_block, static_cast<gr_uint>(part_block[part]));
    const gr_uint* hi = std::lower_bound(lo, to_block, static_cast<gr_uint>(part_block[part + 1]));
    if (lo == hi) continue;
    const int first = static_cast<int>(lo - s.colour_blocks);
    const int count = static_cast<int>(hi - lo);
    const gr_uint base = s.block_start[part_block[part]];
    set_buffer(k, at.seq, &seq[part]);
    if (at.normal != PartArgs::kNoArg) set_buffer(k, at.normal, &normal[part]);
    if (at.factor != PartArgs::kNoArg) set_buffer(k, at.factor, &factor[part]);
    check(clSetKernelArg(k, at.first, sizeof(int), &first), "clSetKernelArg");
    check(clSetKernelArg(k, at.count, sizeof(int), &count), "clSetKernelArg");
    check(clSetKernelArg(k, at.base, sizeof(gr_uint), &base), "clSetKernelArg");
    const size_t items = static_cast<size_t>(count) * local;
    check(clEnqueueNDRangeKernel(queue, k, 1, nullptr, &items, &local, 0, nullptr, nullptr),
          "clEnqueueNDRangeKernel");
  }
}

void Iterations::run_sequential(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                                float* p, const SequentialContacts& s, int iterations) {
  Impl& m = *impl_;
  const size_t n = size.n;
  if (n == 0) return;
  HostArray inputs[kArrays];
  if (s.there) {
    const size_t bytes = (3 * n + 1) * sizeof(float);
    grain_arrays(g, size, inputs);
    m.upload(m.p, p, bytes);
    m.next.reserve(m.ctx, bytes, m.largest);
    m.run_out_n = 0;
  } else {
    m.upload_grains(g, size, p, inputs);
    m.upload_contacts(s);
  }
  Buffer* result = m.sequential_passes(g, prm, size, s, iterations, inputs);
  m.download(*result, p, 3 * n * sizeof(float));
  if (!(s.there && s.stay)) m.download_contacts(s);
}

void Iterations::Impl::download_contacts(const SequentialContacts& s) {
  for (size_t k = 0; k + 1 < part_block.size(); ++k) {
    const size_t first = s.block_start[part_block[k]], count = s.block_start[part_block[k + 1]] - first;
    download(seq[k], s.contacts + first, count * sizeof(gr_seq_contact));
  }
}

Buffer* Iterations::Impl::sequential_passes(const gr_grains& g, const gr_params& prm,
                                            const IterationSizes& size, const SequentialContacts& s,
                                            int iterations, const HostArray* inputs) {
  const size_t n = size.n;
  const size_t local = kGroup, global = (n + kGroup - 1) / kGroup * kGroup;
  Buffer* from = &p;
  Buffer* to = &next;
  // the others' Jacobi group: gr_k_iterate with their arrays and no sums
  if (s.others) {
    HostArray theirs[kArrays];
    grain_arrays(*s.others, size, theirs);
    set_grains(others, *s.others_prm, *s.others, theirs);
    const int count = static_cast<int>(n);
    const gr_uint none = 0;
    for (cl_uint a = kFirstOwn + 2; a <= kFirstOwn + 7; ++a)
      if (a == kFirstOwn + 3) check(clSetKernelArg(others, a, sizeof(gr_uint), &none), "clSetKernelArg");
      else set_buffer(others, a, nullptr);
    check(clSetKernelArg(others, kFirstOwn + 8, sizeof(int), &count), "clSetKernelArg");
  }
  // the contacts: p, seq, block_wave, blocks, first, count, relax, base, wave_start (seq, first,
  // count and base by colour and part)
  set_grains(sequential, prm, g, inputs);
  set_buffer(sequential, kFirstOwn + 2, &block_wave);
  set_buffer(sequential, kFirstOwn + 3, &colour_blocks);
  check(clSetKernelArg(sequential, kFirstOwn + 6, sizeof(float), &s.relax), "clSetKernelArg");
  set_buffer(sequential, kFirstOwn + 8, &wave_start);
  const PartArgs at{kFirstOwn + 1, kFirstOwn + 4, kFirstOwn + 5, kFirstOwn + 7};
  const bool pins = g.targetP && g.targetstiffness;
  if (pins) set_pins(g, prm, n);
  // the shapes, their normal sums sent here and brought back after the passes
  const ShapeArrays* sh = s.shapes && s.shapes->components > 0 ? s.shapes : nullptr;
  if (sh && sh->collider_normal)
    upload(shape_normal, sh->collider_normal, sh->entries * sizeof(float));
  if (sh) set_shapes(*sh, prm, g, inputs, sh->collider_normal ? &shape_normal : nullptr, n);
  for (int it = 0; it < iterations; ++it) {
    if (s.others) {
      set_buffer(others, kFirstOwn, from);
      set_buffer(others, kFirstOwn + 1, to);
      check(clEnqueueNDRangeKernel(queue, others, 1, nullptr, &global, &local, 0, nullptr, nullptr),
            "clEnqueueNDRangeKernel");
      std::swap(from, to);
    }
    set_buffer(sequential, kFirstOwn, from);
    for (size_t c = 0; c < s.colours && s.count > 0; ++c) sweep_colour(sequential, at, s, c);
    if (sh) project_shapes(from, sh->components);
    if (pins) project_pins(from, global);
  }
  if (sh && sh->collider_normal)
    download(shape_normal, sh->collider_normal, sh->entries * sizeof(float));
  return from;
}

bool Iterations::stabilize(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                           float* x, int most, const std::function<bool(int, float)>& go_on,
                           bool there) {
  Impl& m = *impl_;
  const size_t n = size.n;
  if (n == 0 || most <= 0 || (there && !(m.p_taken && m.p_taken_n == n))) return !there;
  const size_t f = sizeof(float);
  constexpr size_t kParts = 16 * kGroup;  // gr_k_largest's work-items
  if (!m.stabilize_grains) {
    cl_int status = CL_SUCCESS;
    m.stabilize_grains = clCreateKernel(m.program, "gr_k_stabilize_grains", &status);
    check(status, "clCreateKernel(gr_k_stabilize_grains)");
    m.largest_part = clCreateKernel(m.program, "gr_k_largest", &status);
    check(status, "clCreateKernel(gr_k_largest)");
  }
  HostArray inputs[kArrays];
  m.upload_grains(g, size, there ? nullptr : x, inputs);  // x to m.p; m.next made room for
  if (there) m.copy_positions(m.p, m.arrays[kP], n);
  m.moved.reserve(m.ctx, n * f, m.largest);
  m.moved_part.reserve(m.ctx, kParts * f, m.largest);
  const int count = static_cast<int>(n);
  cl_kernel k = m.stabilize_grains;
  m.set_grains(k, prm, g, inputs);
  set_buffer(k, kFirstOwn + 2, &m.moved);
  check(clSetKernelArg(k, kFirstOwn + 3, sizeof(int), &count), "clSetKernelArg");
  set_buffer(m.largest_part, 0, &m.moved);
  check(clSetKernelArg(m.largest_part, 1, sizeof(int), &count), "clSetKernelArg");
  set_buffer(m.largest_part, 2, &m.moved_part);
  const size_t local = kGroup, global = (n + kGroup - 1) / kGroup * kGroup, parts = kParts;
  std::vector<float> part(kParts);
  Buffer* from = &m.p;
  Buffer* to = &m.next;
  for (int pass = 0; pass < most; ++pass) {
    set_buffer(k, kFirstOwn, from);
    set_buffer(k, kFirstOwn + 1, to);
    check(clEnqueueNDRangeKernel(m.queue, k, 1, nullptr, &global, &local, 0, nullptr, nullptr),
          "clEnqueueNDRangeKernel");
    std::swap(from, to);
    check(clEnqueueNDRangeKernel(m.queue, m.largest_part, 1, nullptr, &parts, &local, 0, nullptr,
                                 nullptr),
          "clEnqueueNDRangeKernel");
    m.download(m.moved_part, part.data(), kParts * f);
    float moved = 0.0f;
    for (const float v : part) moved = std::max(moved, v);
    if (!go_on(pass, moved)) break;
  }
  if (!there) {
    m.download(*from, x, 3 * n * f);
    return true;
  }
  // the start as it went up, for the final collision test; the prediction moved with it, into
  // a buffer of its own (the search's copy stays the rows' positions); then the start replaced
  m.copy_positions(m.start, m.arrays[kP], n);
  m.start_kept = n;
  m.shifted.reserve(m.ctx, (3 * n + 1) * f, m.largest);
  cl_kernel shift = m.kernel(m.shift, "gr_k_shift");
  const int floats = static_cast<int>(3 * n);
  arg(shift, 0, *m.p_taken), arg(shift, 1, *from), arg(shift, 2, m.arrays[kP]);
  arg(shift, 3, m.shifted), arg(shift, 4, floats);
  m.launch(shift, 3 * n);
  m.p_taken = &m.shifted;
  m.copy_positions(m.arrays[kP], *from, n);
  m.copied_once(m.arrays[kP], x, 3 * n * f);
  return true;
}

bool Iterations::fetch_run(float* p, float* start, size_t n) {
  Impl& m = *impl_;
  if (!m.run_out || m.run_out_n != n) return false;
  m.download(*m.run_out, p, 3 * n * sizeof(float));
  if (start) m.download(m.arrays[kP], start, 3 * n * sizeof(float));
  return true;
}

void Iterations::Impl::each_part(cl_kernel k, cl_uint seq_arg, const SequentialContacts& s,
                                 cl_uint normal_arg, cl_uint factor_arg) {
  const size_t local = kGroup;
  for (size_t part = 0; part + 1 < part_block.size(); ++part) {
    const gr_uint base = s.block_start[part_block[part]];
    const int count = static_cast<int>(s.block_start[part_block[part + 1]] - base);
    if (count == 0) continue;
    set_buffer(k, seq_arg, &seq[part]);
    if (normal_arg != PartArgs::kNoArg) set_buffer(k, normal_arg, &normal[part]);
    if (factor_arg != PartArgs::kNoArg) set_buffer(k, factor_arg, &factor[part]);
    check(clSetKernelArg(k, seq_arg + 1, sizeof(gr_uint), &base), "clSetKernelArg");
    check(clSetKernelArg(k, seq_arg + 2, sizeof(int), &count), "clSetKernelArg");
    const size_t items = (static_cast<size_t>(count) + kGroup - 1) / kGroup * kGroup;
    check(clEnqueueNDRangeKernel(queue, k, 1, nullptr, &items, &local, 0, nullptr, nullptr),
          "clEnqueueNDRangeKernel");
  }
}

cl_kernel Iterations::Impl::kernel(cl_kernel& k, const char* name) {
  if (!k) {
    cl_int status = CL_SUCCESS;
    k = clCreateKernel(program, name, &status);
    check(status, name);
  }
  return k;
}

void Iterations::solve_sequential(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                                  float* p, const SequentialContacts& s, const SequentialSolve& w,
                                  int iterations) {
  Impl& m = *impl_;
  const size_t n = size.n;
  if (n == 0) return;
  const size_t f = sizeof(float);
  const int count = static_cast<int>(n);
  auto per_grain = [&](cl_kernel k) { m.launch(k, n); };
  HostArray inputs[kArrays];
  // a list built on the device came with the same grains' arrays (build_sequential), all but
  // the rows, which clumping reads from these
  const bool p_there = w.p_there && m.p_taken && m.p_taken_n == n;
  m.upload_grains(g, size, p_there ? nullptr : p, inputs, s.built);
  if (p_there) m.copy_positions(m.p, *m.p_taken, n);
  const bool contacts = s.count > 0;
  // whether the contacts carry loads (the warm start runs): the host's flags, or with a
  // resident list those gr_k_keep writes: seq, base, count, warm, scale, loaded
  const bool loaded = s.resident || s.built ? s.keep_warm : w.loaded != nullptr;
  if (s.built) {
    m.upload_blocks(s);
  } else if (!s.resident) {
    m.upload_contacts(s);
    if (contacts && loaded) m.upload(m.carried_flag, w.loaded, s.count);
  } else if (contacts) {
    if (loaded) m.carried_flag.reserve(m.ctx, s.count, m.largest);
    cl_kernel keep = m.kernel(m.keep, "gr_k_keep");
    const int warm = s.keep_warm ? 1 : 0;
    check(clSetKernelArg(keep, 3, sizeof(int), &warm), "clSetKernelArg");
    check(clSetKernelArg(keep, 4, sizeof(float), &s.keep_scale), "clSetKernelArg");
    set_buffer(keep, 5, loaded ? &m.carried_flag : nullptr);
    m.each_part(keep, 0, s);
  }

  // pre-stabilization: x, p, carried, carried_flag, seq, block_wave, blocks, first, count, base,
  // most, wave_start, part
  if (w.x) {
    // the start as it went up, and no carried move yet: made here, not sent
    m.copy_positions(m.stable, m.arrays[kP], n);
    const float zero = 0.0f;
    if (w.take_back) {
      m.carried.reserve(m.ctx, 3 * n * f, m.largest);
      check(
          clEnqueueFillBuffer(m.queue, m.carried.mem, &zero, f, 0, 3 * n * f, 0, nullptr, nullptr),
          "clEnqueueFillBuffer");
    }
    if (contacts && w.most > 0) {
      cl_kernel k = m.kernel(m.stabilize, "gr_k_stabilize");
      m.block_most.reserve(m.ctx, s.blocks * f, m.largest);
      m.set_grains(k, prm, g, inputs);
      set_buffer(k, kFirstOwn, &m.stable);
      set_buffer(k, kFirstOwn + 1, &m.p);
      set_buffer(k, kFirstOwn + 2, w.take_back ? &m.carried : nullptr);
      set_buffer(k, kFirstOwn + 3, w.take_back && loaded ? &m.carried_flag : nullptr);
      set_buffer(k, kFirstOwn + 5, &m.block_wave);
      set_buffer(k, kFirstOwn + 6, &m.colour_blocks);
      set_buffer(k, kFirstOwn + 10, &m.block_most);
      set_buffer(k, kFirstOwn + 11, &m.wave_start);
      Impl::PartArgs at{kFirstOwn + 4, kFirstOwn + 7, kFirstOwn + 8, kFirstOwn + 9};
      at.local_floats = kFirstOwn + 12;
      std::vector<float> block_most(s.blocks);
      for (int pass = 0; pass < w.most; ++pass) {
        for (size_t c = 0; c < s.colours; ++c) m.sweep_colour(k, at, s, c);
        // the pass's largest move (each block is swept once a pass: in one colour, one part)
        m.download(m.block_most, block_most.data(), s.blocks * f);
        float moved = 0.0f;
        for (const float b : block_most) moved = std::max(moved, b);
        if (!w.go_on(pass, moved)) break;
      }
    }
  }
  // the velocity pre-stabilization takes back: v, p, carried, inv_last, n
  const bool velocities = w.take_back || (contacts && loaded);
  // (carry_start may have made them there)
  if (velocities) m.upload_once(m.velocity, w.v ? w.v : g.v, 3 * n * f);
  if (w.x && w.take_back) {
    cl_kernel k = m.kernel(m.take_back, "gr_k_warm_take_back");
    m.set_grains(k, prm, g, inputs);
    set_buffer(k, kFirstOwn, &m.velocity);
    set_buffer(k, kFirstOwn + 1, &m.p);
    set_buffer(k, kFirstOwn + 2, &m.carried);
    check(clSetKernelArg(k, kFirstOwn + 3, sizeof(float), &w.inv_last), "clSetKernelArg");
    check(clSetKernelArg(k, kFirstOwn + 4, sizeof(int), &count), "clSetKernelArg");
    per_grain(k);
    m.forget(m.velocity);  // no longer the host's
  }
  // the pre-stabilized start is the substep's start from here on (g.P); the final collision
  // test reads the start as it went up
  const bool final_test = w.finish && w.finish->colliders && w.finish->v_out;
  if (w.x && final_test) m.copy_positions(m.start, m.arrays[kP], n);
  if (w.x)
    check(clEnqueueCopyBuffer(m.queue, m.stable.mem, m.arrays[kP].mem, 0, 0, 3 * n * f, 0, nullptr, nullptr),
          "clEnqueueCopyBuffer");

  // the warm start, in gauss_seidel.cpp's order
  if (contacts && loaded) {
    // each part's normals and factors (3 and 1 floats a contact: within the largest buffer
    // where the part's contacts, 56 bytes each, are)
    const size_t parts = m.part_block.size() - 1;
    for (std::vector<Buffer>* b : {&m.normal, &m.factor}) {
      for (size_t k = parts; k < b->size(); ++k) (*b)[k].release();
      b->resize(parts);
    }
    for (size_t k = 0; k < parts; ++k) {
      const size_t part = s.block_start[m.part_block[k + 1]] - s.block_start[m.part_block[k]];
      m.normal[k].reserve(m.ctx, 3 * part * f, m.largest);
      m.factor[k].reserve(m.ctx, part * f, m.largest);
    }
    m.repeat.reserve(m.ctx, 3 * n * f, m.largest);
    m.external.reserve(m.ctx, 3 * n * f, m.largest);
    m.balance.reserve(m.ctx, n * f, m.largest);
    m.cold.reserve(m.ctx, n, m.largest);
    m.cut.reserve(m.ctx, sizeof(int), m.largest);
    // each loaded contact's load kept across its normal: prm, grains, p, seq, base, count,
    // loaded, normal, factor
    cl_kernel open = m.kernel(m.warm_open, "gr_k_warm_open");
    m.set_grains(open, prm, g, inputs);
    set_buffer(open, kFirstOwn, &m.p);
    set_buffer(open, kFirstOwn + 4, &m.carried_flag);
    m.each_part(open, kFirstOwn + 1, s, kFirstOwn + 5, kFirstOwn + 6);
    // what the scaled loads give each grain: seq, block_wave, blocks, first, count, base,
    // normal, factor, repeat, wave_start
    cl_kernel repeat = m.kernel(m.warm_repeat, "gr_k_warm_repeat");
    set_buffer(repeat, 1, &m.block_wave);
    set_buffer(repeat, 2, &m.colour_blocks);
    set_buffer(repeat, 8, &m.repeat);
    set_buffer(repeat, 9, &m.wave_start);
    auto sum_repeat = [&] {
      const float zero = 0.0f;
      check(clEnqueueFillBuffer(m.queue, m.repeat.mem, &zero, f, 0, 3 * n * f, 0, nullptr, nullptr),
            "clEnqueueFillBuffer");
      for (size_t c = 0; c < s.colours; ++c) m.sweep_colour(repeat, Impl::PartArgs{0, 3, 4, 5, 6, 7}, s, c);
    };
    sum_repeat();
    // each grain's balance: prm, grains, v, p, repeat, external, balance, n
    cl_kernel balance = m.kernel(m.warm_balance, "gr_k_warm_balance");
    m.set_grains(balance, prm, g, inputs);
    set_buffer(balance, kFirstOwn, &m.velocity);
    set_buffer(balance, kFirstOwn + 1, &m.p);
    set_buffer(balance, kFirstOwn + 2, &m.repeat);
    set_buffer(balance, kFirstOwn + 3, &m.external);
    set_buffer(balance, kFirstOwn + 4, &m.balance);
    check(clSetKernelArg(balance, kFirstOwn + 5, sizeof(int), &count), "clSetKernelArg");
    per_grain(balance);
    // each contact's factor: seq, base, count, balance, factor
    cl_kernel factor = m.kernel(m.warm_factor, "gr_k_warm_factor");
    set_buffer(factor, 3, &m.balance);
    m.each_part(factor, 0, s, Impl::PartArgs::kNoArg, 4);
    // grains thrown off balance start cold with their contacts, until none is: prm, grains,
    // repeat, external, cold, n; then seq, base, count, cold, factor, cut
    cl_kernel cold = m.kernel(m.warm_cold, "gr_k_warm_cold");
    m.set_grains(cold, prm, g, inputs);
    set_buffer(cold, kFirstOwn, &m.repeat);
    set_buffer(cold, kFirstOwn + 1, &m.external);
    set_buffer(cold, kFirstOwn + 2, &m.cold);
    check(clSetKernelArg(cold, kFirstOwn + 3, sizeof(int), &count), "clSetKernelArg");
    cl_kernel cut = m.kernel(m.warm_cut, "gr_k_warm_cut");
    set_buffer(cut, 3, &m.cold);
    set_buffer(cut, 5, &m.cut);
    for (int any = 1; any;) {
      any = 0;
      sum_repeat();
      per_grain(cold);
      m.send(m.cut, &any, sizeof any);
      m.each_part(cut, 0, s, Impl::PartArgs::kNoArg, 4);
      m.download(m.cut, &any, sizeof any);
    }
    // the loads scaled and applied: p, seq, block_wave, blocks, first, count, base, normal,
    // factor, wave_start
    cl_kernel apply = m.kernel(m.warm_apply, "gr_k_warm_apply");
    set_buffer(apply, 0, &m.p);
    set_buffer(apply, 2, &m.block_wave);
    set_buffer(apply, 3, &m.colour_blocks);
    set_buffer(apply, 9, &m.wave_start);
    for (size_t c = 0; c < s.colours; ++c) m.sweep_colour(apply, Impl::PartArgs{1, 4, 5, 6, 7, 8}, s, c);
  }

  Buffer* result = m.sequential_passes(g, prm, size, s, iterations, inputs);
  if (w.finish && w.finish->impact_collider) {
    // the impact data's loads: each collider contact's into its grain's slot (zero else):
    // prm, grains, seq, base, count, dx
    const float zero = 0.0f;
    const size_t slots = 3 * GR_MAX_PLANES * n * f;
    m.collider_dx.reserve(m.ctx, slots, m.largest);
    check(clEnqueueFillBuffer(m.queue, m.collider_dx.mem, &zero, f, 0, slots, 0, nullptr, nullptr),
          "clEnqueueFillBuffer");
    cl_kernel k = m.kernel(m.impact_loads, "gr_k_impact_loads");
    m.set_grains(k, prm, g, inputs);
    set_buffer(k, kFirstOwn + 3, &m.collider_dx);
    m.each_part(k, kFirstOwn, s);
  }
  if (w.finish) {
    m.finish_substep(g, prm, inputs, result, *w.finish, velocities, w.x ? &m.start : &m.arrays[kP],
                     n);
  } else {
    m.download(*result, p, 3 * n * f);
    if (w.x) m.download(m.stable, w.x, 3 * n * f);
    if (w.take_back) m.download(m.velocity, w.v, 3 * n * f);
  }
  if (!s.stay) m.download_contacts(s);
  if (s.loaded) {
    gr_uint count_loaded = 0;
    m.seq_loaded_count.reserve(m.ctx, sizeof(gr_uint), m.largest);
    m.send(m.seq_loaded_count, &count_loaded, sizeof count_loaded);
    cl_kernel k = m.kernel(m.seq_loaded, "gr_k_seq_loaded");
    set_buffer(k, 3, &m.seq_loaded_count);
    m.each_part(k, 0, s);
    m.download(m.seq_loaded_count, &count_loaded, sizeof count_loaded);
    *s.loaded = count_loaded;
  }
}

void Iterations::Impl::finish_substep(const gr_grains& g, const gr_params& prm,
                                      const HostArray* inputs, Buffer* result, const SubstepEnd& e,
                                      bool velocity_there, Buffer* start_there, size_t n) {
  const SubstepEnd* end = &e;
  const size_t f = sizeof(float);
  const int count = static_cast<int>(n);
  const bool final_test = end->colliders && end->v_out;
  // the substep's end: prm, grains, v, force, force_uniform, p, origin, P_out, v_out, n, keep
  // (the start velocities as pre-stabilization left them there, or as they are)
  if (!velocity_there) upload_once(velocity, g.v, 3 * n * f);
  const int uniform = end->force_uniform ? 1 : 0;
  upload_once(force, end->force, (uniform ? 3 : 3 * n) * f);
  stats_P.reserve(ctx, 3 * n * f, largest);
  if (end->v_out) end_v.reserve(ctx, 3 * n * f, largest);
  cl_kernel k = kernel(finish, "gr_k_finish");
  set_grains(k, prm, g, inputs);
  set_buffer(k, kFirstOwn, &velocity);
  set_buffer(k, kFirstOwn + 1, end->force ? &force : nullptr);
  check(clSetKernelArg(k, kFirstOwn + 2, sizeof(int), &uniform), "clSetKernelArg");
  set_buffer(k, kFirstOwn + 3, result);
  for (cl_uint a = 0; a < 3; ++a)
    check(clSetKernelArg(k, kFirstOwn + 4 + a, sizeof(float), &end->origin[a]), "clSetKernelArg");
  set_buffer(k, kFirstOwn + 7, &stats_P);
  set_buffer(k, kFirstOwn + 8, end->v_out ? &end_v : nullptr);
  check(clSetKernelArg(k, kFirstOwn + 9, sizeof(int), &count), "clSetKernelArg");
  const int keep = end->keep_velocity ? 1 : 0;
  check(clSetKernelArg(k, kFirstOwn + 10, sizeof(int), &keep), "clSetKernelArg");
  launch(k, n);
  const bool impacts = end->impact_collider != nullptr;
  if (final_test || impacts) {
    // the final collision test of what it wrote (the colliders the planes took, sent once a
    // substep), with the impact data beside it where they are asked for (from collider_dx:
    // gauss_seidel's contacts' loads or jacobi's sums): prm, grains, colliders, count (0: no
    // test), start, origin, P_out, v_out, n; then dx, plane_collider, and each slot's collider,
    // impulse, normal and point (null: no impact data)
    const int colliders = final_test ? static_cast<int>(end->collider_count) : 0;
    if (colliders > 0)
      upload_once(plane_colliders, end->colliders, colliders * sizeof(gr_collider));
    cl_kernel c = kernel(final_collision, "gr_k_final_collision");
    set_grains(c, prm, g, inputs);
    set_buffer(c, kFirstOwn, colliders > 0 ? &plane_colliders : nullptr);
    check(clSetKernelArg(c, kFirstOwn + 1, sizeof(int), &colliders), "clSetKernelArg");
    set_buffer(c, kFirstOwn + 2, start_there);
    for (cl_uint a = 0; a < 3; ++a)
      check(clSetKernelArg(c, kFirstOwn + 3 + a, sizeof(float), &end->origin[a]), "clSetKernelArg");
    set_buffer(c, kFirstOwn + 6, &stats_P);
    set_buffer(c, kFirstOwn + 7, &end_v);
    check(clSetKernelArg(c, kFirstOwn + 8, sizeof(int), &count), "clSetKernelArg");
    const size_t slots = GR_MAX_PLANES * n;
    if (impacts) {
      impact_collider.reserve(ctx, slots * sizeof(int32_t), largest);
      for (Buffer* b : {&impact_impulse, &impact_normal, &impact_point})
        b->reserve(ctx, 3 * slots * f, largest);
    }
    Buffer* const impact_args[] = {&collider_dx,    &plane_collider, &impact_collider,
                                   &impact_impulse, &impact_normal,  &impact_point};
    for (cl_uint a = 0; a < 6; ++a)
      set_buffer(c, kFirstOwn + 9 + a, impacts ? impact_args[a] : nullptr);
    set_buffer(c, kFirstOwn + 15, colliders > 0 ? meshes() : nullptr);  // (set_meshes)
    launch(c, n);
    if (impacts) fetch_impacts(*end, slots);
  }
  written_n = n;
  // what it wrote, kept for the next substep's start (carry_start): the positions copied
  // (the statistics patch stats_P with the host's), the velocities where they are (nothing
  // else writes end_v)
  carry_P.reserve(ctx, 3 * n * f, largest);
  check(clEnqueueCopyBuffer(queue, stats_P.mem, carry_P.mem, 0, 0, 3 * n * f, 0, nullptr, nullptr),
        "clEnqueueCopyBuffer");
  carry_n = n;
  carry_v_n = end->v_out ? n : 0;
  if (!end->stay) {
    download(stats_P, end->P_out, 3 * n * f);
    download(end_v, end->v_out, 3 * n * f);
  }
}

void Iterations::Impl::fetch_impacts(const SubstepEnd& end, size_t slots) {
  const size_t f = sizeof(float);
  // the filled slots packed (44 bytes each), the others -1 and zeros here: collider, impulse,
  // normal, point, slots, count, index, value
  gr_uint filled = 0;
  impact_count.reserve(ctx, sizeof(gr_uint), largest);
  impact_index.reserve(ctx, 2 * slots * sizeof(int32_t), largest);
  impact_value.reserve(ctx, 9 * slots * f, largest);
  send(impact_count, &filled, sizeof filled);
  cl_kernel pack = kernel(impact_pack, "gr_k_impact_pack");
  set_buffer(pack, 0, &impact_collider);
  set_buffer(pack, 1, &impact_impulse);
  set_buffer(pack, 2, &impact_normal);
  set_buffer(pack, 3, &impact_point);
  const int slot_count = static_cast<int>(slots);
  check(clSetKernelArg(pack, 4, sizeof(int), &slot_count), "clSetKernelArg");
  set_buffer(pack, 5, &impact_count);
  set_buffer(pack, 6, &impact_index);
  set_buffer(pack, 7, &impact_value);
  launch(pack, slots);
  download(impact_count, &filled, sizeof filled);
  impact_index_host.resize(2 * size_t(filled));
  impact_value_host.resize(9 * size_t(filled));
  download(impact_index, impact_index_host.data(), impact_index_host.size() * sizeof(int32_t));
  download(impact_value, impact_value_host.data(), impact_value_host.size() * f);
  std::fill_n(end.impact_collider, slots, -1);
  for (float* a : {end.impact_impulse, end.impact_normal, end.impact_point})
    std::fill_n(a, 3 * slots, 0.0f);
  for (size_t r = 0; r < filled; ++r) {
    const size_t e = static_cast<size_t>(impact_index_host[2 * r]);
    const float* value = &impact_value_host[9 * r];
    end.impact_collider[e] = impact_index_host[2 * r + 1];
    std::copy_n(value, 3, end.impact_impulse + 3 * e);
    std::copy_n(value + 3, 3, end.impact_normal + 3 * e);
    std::copy_n(value + 6, 3, end.impact_point + 3 * e);
  }
}

void Iterations::Impl::stats_positions(const float* P, size_t n,
                                       const std::vector<gr_uint>* written_there) {
  if (!(written_there && written_n == n)) {
    upload(stats_P, P, 3 * n * sizeof(float));
    written_n = 0;
    return;
  }
  patch(stats_P, P, *written_there, false, 0);
}

void Iterations::Impl::patch(Buffer& to, const float* P, const std::vector<gr_uint>& index,
                             bool index_there, int slot) {
  const size_t count = index.size();
  if (count == 0) return;
  std::vector<float>& values = patch_host[slot];
  values.resize(3 * count);
  for (size_t k = 0; k < count; ++k)
    std::copy_n(P + 3 * size_t(index[k]), 3, values.begin() + 3 * k);
  if (!index_there) upload(patch_index, index.data(), count * sizeof(gr_uint));
  upload(patch_values, values.data(), values.size() * sizeof(float));
  cl_kernel k = kernel(scatter3, "gr_k_scatter3");
  const int items = static_cast<int>(count);
  arg(k, 0, to), arg(k, 1, patch_index), arg(k, 2, patch_values), arg(k, 3, items);
  launch(k, count);
}

void Iterations::order_waves(const gr_uint* colour_blocks, const gr_uint* colour_start,
                             size_t colours, std::vector<gr_uint>* block_wave,
                             std::vector<gr_uint>* wave_start) {
  Impl& m = *impl_;
  const size_t u = sizeof(gr_uint), per = sizeof(gr_seq_contact);
  const size_t total = m.held, blocks = m.part_block.back(), n = m.grains;
  // the last list is no longer needed (its loads were looked up): it holds the copies
  m.seq_old.reserve(m.ctx, std::max<size_t>(total, 1) * per, m.largest);
  if (m.built_flags) m.flag_copy.reserve(m.ctx, total, m.largest);
  const gr_ulong zero = 0;
  m.marks.reserve(m.ctx, 2 * n * sizeof(gr_ulong), m.largest);
  check(clEnqueueFillBuffer(m.queue, m.marks.mem, &zero, sizeof zero, 0, 2 * n * sizeof(gr_ulong),
                            0, nullptr, nullptr),
        "clEnqueueFillBuffer");
  m.wave_of.reserve(m.ctx, total * u, m.largest);
  m.wave_ends.reserve(m.ctx, (total + blocks + 1) * u, m.largest);
  m.block_waves.reserve(m.ctx, (blocks + 1) * u, m.largest);
  m.upload(m.colour_blocks, colour_blocks, blocks * u);
  cl_kernel k = m.kernel(m.seq_waves, "gr_k_seq_waves");
  set_buffer(k, 0, &m.seq[0]);
  set_buffer(k, 1, &m.seq_old);
  set_buffer(k, 2, m.built_flags ? &m.carried_flag : nullptr);
  set_buffer(k, 3, m.built_flags ? &m.flag_copy : nullptr);
  set_buffer(k, 4, &m.marks);
  set_buffer(k, 5, &m.wave_of);
  set_buffer(k, 6, &m.wave_ends);
  set_buffer(k, 7, &m.seq_block_start);
  set_buffer(k, 8, &m.colour_blocks);
  set_buffer(k, 11, &m.block_waves);
  for (size_t c = 0; c < colours; ++c) {
    const int first = static_cast<int>(colour_start[c]);
    const int count = static_cast<int>(colour_start[c + 1] - colour_start[c]);
    check(clSetKernelArg(k, 9, sizeof(int), &first), "clSetKernelArg");
    check(clSetKernelArg(k, 10, sizeof(int), &count), "clSetKernelArg");
    m.launch(k, static_cast<size_t>(count));
  }
  // each block's first wave, here; each wave's first contact, there
  std::vector<gr_uint> waves(blocks);
  m.download(m.block_waves, waves.data(), blocks * u);
  block_wave->assign(blocks + 1, 0u);
  for (size_t b = 0; b < blocks; ++b) (*block_wave)[b + 1] = (*block_wave)[b] + waves[b];
  const size_t count = block_wave->back();
  m.upload(m.block_wave, block_wave->data(), (blocks + 1) * u);
  m.wave_start.reserve(m.ctx, (count + 1) * u, m.largest);
  const int block_count = static_cast<int>(blocks);
  cl_kernel starts = m.kernel(m.seq_wave_starts, "gr_k_seq_wave_starts");
  set_buffer(starts, 0, &m.wave_ends);
  set_buffer(starts, 1, &m.seq_block_start);
  set_buffer(starts, 2, &m.block_wave);
  check(clSetKernelArg(starts, 3, sizeof(int), &block_count), "clSetKernelArg");
  set_buffer(starts, 4, &m.wave_start);
  m.launch(starts, blocks);
  wave_start->resize(count + 1);
  m.download(m.wave_start, wave_start->data(), count * u);
  (*wave_start)[count] = static_cast<gr_uint>(total);
}

void Iterations::Impl::copy_positions(Buffer& to, const Buffer& from, size_t n) {
  const size_t f = sizeof(float);
  const float zero = 0.0f;
  to.reserve(ctx, (3 * n + 1) * f, largest);
  check(clEnqueueCopyBuffer(queue, from.mem, to.mem, 0, 0, 3 * n * f, 0, nullptr, nullptr),
        "clEnqueueCopyBuffer");
  check(clEnqueueFillBuffer(queue, to.mem, &zero, f, 3 * n * f, f, 0, nullptr, nullptr),
        "clEnqueueFillBuffer");
}

void Iterations::Impl::launch(cl_kernel k, size_t items) {
  const size_t local = kGroup, global = (std::max<size_t>(items, 1) + kGroup - 1) / kGroup * kGroup;
  check(clEnqueueNDRangeKernel(queue, k, 1, nullptr, &global, &local, 0, nullptr, nullptr),
        "clEnqueueNDRangeKernel");
}

void Iterations::fetch_contacts(const SequentialContacts& s) {
  impl_->download_contacts(s);
}

bool Iterations::build_sequential(const gr_grains& g, const gr_params& prm,
                                  const IterationSizes& size, const int* id,
                                  const int* plane_collider, bool warm, float scale,
                                  size_t block_grains, bool rows_there, BuiltList* out) {
  Impl& m = *impl_;
  const size_t n = size.n, u = sizeof(gr_uint), per = sizeof(gr_seq_contact);
  const size_t blocks = (n + block_grains - 1) / block_grains;
  const size_t words = (blocks + 31) / 32;
  if (n == 0 || blocks * words * u > (size_t(64) << 20)) return false;
  // the loads are looked up in the last list, which must be whole in one buffer
  if (warm && !(m.held_whole && m.seq.size() == 1)) return false;
  const int count = static_cast<int>(n);
  // the rows where the device found them, else g's sent
  const bool there = rows_there && m.rows_found && g.nbr_offsets;
  gr_grains sent = g;
  if (there) sent.nbr_offsets = sent.nbr_indices = nullptr;
  HostArray inputs[kArrays];
  m.upload_grains(sent, size, nullptr, inputs);
  // gr_k_seq_count's and gr_k_seq_fill's common arguments: prm, the grains, id, plane_collider,
  // n, the counts or offsets
  auto set_build = [&](cl_kernel k) {
    m.set_grains(k, prm, sent, inputs);
    if (there) {
      set_buffer(k, 1 + kNbrOffsets, &m.nb_offsets);
      set_buffer(k, 1 + kNbrIndices, &m.nb_indices);
    }
    set_buffer(k, kFirstOwn, id ? &m.id : nullptr);
    set_buffer(k, kFirstOwn + 1, plane_collider ? &m.plane_collider : nullptr);
    check(clSetKernelArg(k, kFirstOwn + 2, sizeof(int), &count), "clSetKernelArg");
    set_buffer(k, kFirstOwn + 3, &m.seq_offsets);
  };
  m.upload_once(m.id, id, n * sizeof(int));
  if (!size.planes_there)
    m.upload(m.plane_collider, plane_collider, size.plane_entries * sizeof(int));
  // each grain's contacts counted, their offsets
  m.seq_offsets.reserve(m.ctx, (n + 1) * u, m.largest);
  cl_kernel counter = m.kernel(m.seq_count, "gr_k_seq_count");
  set_build(counter);
  m.launch(counter, n);
  m.scan(m.seq_offsets, n);
  gr_uint total = 0;
  m.download(m.seq_offsets, &total, u, n * u);
  if (size_t(total) * per > m.largest) return false;
  // the last list moves aside for the lookup; the new one is written where the solve reads it
  if (m.seq.empty()) m.seq.resize(1);
  for (size_t k = 1; k < m.seq.size(); ++k) m.seq[k].release();
  m.seq.resize(1);
  std::swap(m.seq[0], m.seq_old);
  const size_t old_count = m.held;
  m.seq[0].reserve(m.ctx, size_t(total) * per, m.largest);
  cl_kernel fill = m.kernel(m.seq_fill, "gr_k_seq_fill");
  set_build(fill);
  set_buffer(fill, kFirstOwn + 4, &m.seq[0]);
  m.launch(fill, n);
  m.held = total;
  m.held_whole = true;
  m.grains = n;
  m.part_block.assign({0, blocks});
  // each block's first contact
  const int grains_a_block = static_cast<int>(block_grains), block_count = static_cast<int>(blocks);
  m.seq_block_start.reserve(m.ctx, (blocks + 1) * u, m.largest);
  cl_kernel starts = m.kernel(m.seq_blocks, "gr_k_seq_blocks");
  set_buffer(starts, 0, &m.seq_offsets);
  check(clSetKernelArg(starts, 1, sizeof(int), &count), "clSetKernelArg");
  check(clSetKernelArg(starts, 2, sizeof(int), &grains_a_block), "clSetKernelArg");
  check(clSetKernelArg(starts, 3, sizeof(int), &block_count), "clSetKernelArg");
  set_buffer(starts, 4, &m.seq_block_start);
  m.launch(starts, blocks + 1);
  // the blocks' links
  const int contacts = static_cast<int>(total), row_words = static_cast<int>(words);
  const gr_uint zero = 0;
  m.seq_links_bits.reserve(m.ctx, blocks * words * u, m.largest);
  check(clEnqueueFillBuffer(m.queue, m.seq_links_bits.mem, &zero, u, 0, blocks * words * u, 0,
                            nullptr, nullptr),
        "clEnqueueFillBuffer");
  cl_kernel links = m.kernel(m.seq_links, "gr_k_seq_links");
  set_buffer(links, 0, &m.seq[0]);
  check(clSetKernelArg(links, 1, sizeof(int), &contacts), "clSetKernelArg");
  check(clSetKernelArg(links, 2, sizeof(int), &grains_a_block), "clSetKernelArg");
  check(clSetKernelArg(links, 3, sizeof(int), &row_words), "clSetKernelArg");
  set_buffer(links, 4, &m.seq_links_bits);
  m.launch(links, total);
  // the carried loads, by key in the last list's loaded contacts
  m.built_flags = warm && total > 0;
  if (m.built_flags) {
    int bits = 4;
    while ((size_t(1) << bits) < 2 * old_count) ++bits;
    const size_t slots = size_t(1) << bits;
    m.seq_table_slots.reserve(m.ctx, slots * u, m.largest);
    check(clEnqueueFillBuffer(m.queue, m.seq_table_slots.mem, &zero, u, 0, slots * u, 0, nullptr,
                              nullptr),
          "clEnqueueFillBuffer");
    const int olds = static_cast<int>(old_count);
    cl_kernel table = m.kernel(m.seq_table, "gr_k_seq_table");
    set_buffer(table, 0, &m.seq_old);
    check(clSetKernelArg(table, 1, sizeof(int), &olds), "clSetKernelArg");
    check(clSetKernelArg(table, 2, sizeof(int), &bits), "clSetKernelArg");
    set_buffer(table, 3, &m.seq_table_slots);
    m.launch(table, old_count);
    m.carried_flag.reserve(m.ctx, total, m.largest);
    cl_kernel lookup = m.kernel(m.seq_lookup, "gr_k_seq_lookup");
    set_buffer(lookup, 0, &m.seq[0]);
    check(clSetKernelArg(lookup, 1, sizeof(int), &contacts), "clSetKernelArg");
    set_buffer(lookup, 2, &m.seq_old);
    check(clSetKernelArg(lookup, 3, sizeof(int), &bits), "clSetKernelArg");
    set_buffer(lookup, 4, &m.seq_table_slots);
    check(clSetKernelArg(lookup, 5, sizeof(float), &scale), "clSetKernelArg");
    set_buffer(lookup, 6, &m.carried_flag);
    m.launch(lookup, total);
  }
  out->count = total;
  out->words = words;
  out->block_start.resize(blocks + 1);
  out->links.resize(blocks * words);
  m.download(m.seq_block_start, out->block_start.data(), (blocks + 1) * u);
  m.download(m.seq_links_bits, out->links.data(), blocks * words * u);
  return true;
}

}  // namespace grains::opencl
