// The grains PBD substep (DESIGN §4). Glue only: it fills the kernels' plain-data inputs, runs
// the neighbour search and the collider queries, and loops over grains calling the per-grain
// math in kernels/*.h. Order of one substep:
//   1. predict p = P + dt (v + dt f/m)                                  (kernels/velocity.h)
//   2. neighbour candidates from p (neighbor_query_scale, max_neighbors) and one collider plane
//      per grain (the nearest collider within range), once, or every iteration when asked
//   3. constraint_iterations Jacobi iterations: gather, average, over-relax (kernels/iterate.h),
//      Chebyshev-extrapolated when chebyshev_rho > 0;
//      friction is its own pass after every iteration (accurate_friction) or after the loop.
//      Rigid shape matching, then pins, are their own constraint groups, projected after each
//      iteration's averaged update (Gauss-Seidel across groups, Jacobi within one, as Macklin
//      et al. 2014 Alg. 1): averaged in with a grain's contacts, a goal would pull only 1/count
//      of the way and a landing cube deformed by 12% of its side; projected, the components are
//      rigid after every iteration. Goals per component (kernels/shapes.h); pins per
//      grain (kernels/pin.h).
//   4. v from the motion, blend and caps, drift (kernels/velocity.h); the final collision pass
//      (swept, so thin and moving colliders hold); write P and v; collider impulses;
//      stats.
//   5. explicit constraints: strain from the end positions, breaking, remove strands (the caller
//      removes the primitives marked dead).
// Coordinates: a substep computes relative to local_origin (0 unless the grains' box is far from
// the world origin compared with its size), so iterations on grains far away keep corrections
// below the world coordinates' float step; colliders are queried at world positions.
// Explicit constraints join the iterations through a per-grain adjacency (CSR rows of (other
// endpoint, primitive)) built once per substep from the primitives, so each grain gathers its own
// constraint corrections like its contacts.
// Every loop over grains is an `omp parallel for` in which each grain writes only its own slots,
// so the result is bit-identical for any thread count and any schedule: the Jacobi iterations and
// the friction pass take chunks dynamically (crowded and empty regions cost differently), the
// rest is static; stats are reduced serially.
#include "nodes/grains/solver.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "engine/buffer.h"
#include "nodes/grains/kernels/distance.h"
#include "nodes/grains/kernels/iterate.h"
#include "nodes/grains/kernels/row_stats.h"
static_assert(grains::GrainsSolver::kContactSlots == GR_MAX_PLANES, "contact slots = planes");
#include "nodes/grains/history.h"
#include "nodes/grains/kernels/mass_shock.h"
#include "nodes/grains/kernels/velocity.h"
#include "nodes/grains/opencl/iterations.h"
#include "nodes/grains/shapes.h"
#include "nodes/grains/sleep_rows.h"
#include "nodes/grains/substep_context.h"

namespace grains {
namespace {

gr_params make_params(const GrainsSettings& s) {
  gr_params k;
  std::memset(&k, 0, sizeof k);
  // the table's KERNEL rows, as evaluated
#define GR_COPY_KERNEL(name) k.name = s.name;
#define GR_COPY_HOST(name)
#define GR_PARAM(kind, name, def, home, modifiers, meaning) GR_COPY_##home(name)
#include "nodes/grains/kernels/param_table.h"
#undef GR_PARAM
#undef GR_COPY_HOST
#undef GR_COPY_KERNEL
  k.dt = s.dt;
  k.stiffness_denominator =
      static_cast<float>(std::max(1, s.substeps) * std::max(1, s.constraint_iterations));
  // Clumping pulls two grains that are apart toward contact by a fraction of their gap each
  // substep, and PBD makes a move a speed move / dt: at the solver's substeps that is the help
  // page's clumping, but the finer substeps error control takes would pull as hard in a fraction
  // of the time, a speed growing as 1 / dt (settle_10k with clumping at the defaults, 256
  // substeps: 17 MJ of kinetic energy in two frames). Scaled by (dt / base_dt)^2 the pull is a
  // force: at any substep the same acceleration, at most iterations x weight x gap / base_dt^2.
  if (s.base_dt > 0 && s.dt < s.base_dt) k.clumping_weight *= (s.dt / s.base_dt) * (s.dt / s.base_dt);
  const MassShock shock = s.mass_shock();
  k.mass_shock = static_cast<int>(shock);
  // local: "because of the approximation of the exponential used, the effective shock scaling
  // power is clamped to approximately seven" (help page)
  k.shock_power = shock == MassShock::Local ? std::min(s.shock_scaling_power, 7.0f)
                                            : s.shock_scaling_power;
  k.shock_inv_separation = s.particle_separation > 0 ? 1.0f / s.particle_separation : 0.0f;
  Vec3 axis = normalized(s.shock_axis);
  k.shock_axis_x = axis.x;
  k.shock_axis_y = axis.y;
  k.shock_axis_z = axis.z;
  k.shock_origin_x = s.shock_origin.x;
  k.shock_origin_y = s.shock_origin.y;
  k.shock_origin_z = s.shock_origin.z;
  return k;
}

inline Vec3 to_vec(gr_float3 a) { return {a.x, a.y, a.z}; }

// grain i's id (GrainsData::id), or its index when the caller gives none
inline int32_t grain_id(const GrainsData& d, size_t i) {
  return d.id ? d.id[i] : static_cast<int32_t>(i);
}

// Union-find root with path halving.
int32_t find_root(std::vector<int32_t>& parent, int32_t a) {
  while (parent[a] != a) a = parent[a] = parent[parent[a]];
  return a;
}

// The origin a substep computes in. Float positions far from the world origin lose small
// corrections (at 100 m one float step is 7.6e-6 m, so a hanging chain's per-iteration pulls
// vanish and it stretched 3.3x the Jacobi estimate). Along an axis where the grains' box lies
// farther from 0 than twice its own size S (a power of two at least the box's largest extent),
// the substep works relative to the box centre rounded to a multiple of S. Every coordinate x
// then lies within S of the origin o while both exceed 1.5 S, so x / o is within [0.6, 1.67]:
// x - o is exact (Sterbenz), and so is adding o back, so a grain that does not move keeps its
// world position bit for bit. Near the origin the shift is 0 and nothing changes. box_origin:
// that origin for the box [lo, hi] of the grains' finite positions (lo > hi: none), which
// local_origin measures here (an end held on the device measures it there: write_back).
Vec3 box_origin(const float lo_f[3], const float hi_f[3]) {
  if (!(lo_f[0] <= hi_f[0])) return {};
  const double lo[3] = {lo_f[0], lo_f[1], lo_f[2]}, hi[3] = {hi_f[0], hi_f[1], hi_f[2]};
  double extent = 0;
  for (int a = 0; a < 3; ++a) extent = std::max(extent, hi[a] - lo[a]);
  const double S = std::exp2(std::ceil(std::log2(std::max(extent, 1e-6))));
  double o[3];
  for (int a = 0; a < 3; ++a) {
    const double centre = 0.5 * (lo[a] + hi[a]);
    o[a] = std::fabs(centre) > 2 * S ? std::round(centre / S) * S : 0.0;
  }
  return {static_cast<float>(o[0]), static_cast<float>(o[1]), static_cast<float>(o[2])};
}

Vec3 local_origin(const float* P, size_t n, int threads) {
  const float inf = std::numeric_limits<float>::infinity();
  float lx = inf, ly = inf, lz = inf, hx = -inf, hy = -inf, hz = -inf;
  const long ln = static_cast<long>(n);
#pragma omp parallel for schedule(static) num_threads(threads) \
    reduction(min : lx, ly, lz) reduction(max : hx, hy, hz)
  for (long i = 0; i < ln; ++i) {
    const float x = P[3 * i], y = P[3 * i + 1], z = P[3 * i + 2];
    if (!(std::isfinite(x) && std::isfinite(y) && std::isfinite(z))) continue;
    lx = std::min(lx, x), hx = std::max(hx, x);
    ly = std::min(ly, y), hy = std::max(hy, y);
    lz = std::min(lz, z), hz = std::max(hz, z);
  }
  const float lo[3] = {lx, ly, lz}, hi[3] = {hx, hy, hz};
  return box_origin(lo, hi);
}

}  // namespace

void GrainsSolver::drop_constrained_pairs(int threads) {
  const size_t n = neighbors_.offsets.size() - 1;
  const long ln = static_cast<long>(n);
  uint32_t* idx = neighbors_.indices.data();
  const uint32_t* off = neighbors_.offsets.data();
  row_kept_.resize(n);
  // each row keeps its unconstrained entries at its front, in order
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long i = 0; i < ln; ++i) {
    const uint32_t cb = con_offsets_[i], ce = con_offsets_[i + 1];
    uint32_t w = off[i];
    for (uint32_t k = off[i]; k < off[i + 1]; ++k) {
      const uint32_t j = idx[k];
      bool joined = false;
      for (uint32_t c = cb; c < ce; ++c) joined |= con_other_[c] == j;
      if (!joined) idx[w++] = j;
    }
    row_kept_[i] = w - off[i];
  }
  // close the gaps: a row moves only towards the front, so rows are moved in order
  uint32_t total = 0;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t from = neighbors_.offsets[i], kept = row_kept_[i];
    neighbors_.offsets[i] = total;
    if (from != total) std::memmove(idx + total, idx + from, kept * sizeof(uint32_t));
    total += kept;
  }
  neighbors_.offsets[n] = total;
  neighbors_.indices.resize(total);
}

// The constraint adjacency: row i lists (other endpoint, primitive) for every valid primitive
// touching grain i, in primitive order (a serial fill: deterministic, O(m)).
void GrainsSolver::build_constraints(const GrainsData& d) {
  const size_t n = d.n, m = d.prim_count;
  const int32_t* e = d.prim_points;
  auto valid = [&](size_t p) {
    int32_t a = e[2 * p], b = e[2 * p + 1];
    return a >= 0 && b >= 0 && static_cast<size_t>(a) < n && static_cast<size_t>(b) < n && a != b;
  };
  con_offsets_.assign(n + 1, 0);
  for (size_t p = 0; p < m; ++p)
    if (valid(p)) {
      ++con_offsets_[e[2 * p] + 1];
      ++con_offsets_[e[2 * p + 1] + 1];
    }
  for (size_t i = 0; i < n; ++i) con_offsets_[i + 1] += con_offsets_[i];
  con_other_.resize(con_offsets_[n]);
  con_prim_.resize(con_offsets_[n]);
  degree_.assign(n, 0);  // fill cursor
  for (size_t p = 0; p < m; ++p) {
    if (!valid(p)) continue;
    uint32_t a = static_cast<uint32_t>(e[2 * p]), b = static_cast<uint32_t>(e[2 * p + 1]);
    uint32_t ka = con_offsets_[a] + degree_[a]++, kb = con_offsets_[b] + degree_[b]++;
    con_other_[ka] = b;
    con_prim_[ka] = static_cast<uint32_t>(p);
    con_other_[kb] = a;
    con_prim_[kb] = static_cast<uint32_t>(p);
  }
}

// Step 5: strain from the end-of-substep positions d.P (and the start P0_ for the accumulating
// mode), breaking, remove strands. Marks removed primitives in d.prim_dead.
void GrainsSolver::update_constraints(GrainsData& d, const GrainsSettings& s, int threads,
                                      GrainsStats* stats) {
  const size_t n = d.n, m = d.prim_count;
  const long lm = static_cast<long>(m);
  const int32_t* e = d.prim_points;
  uint8_t* dead = d.prim_dead;
  if (!dead) {
    dead_.assign(m, 0);
    dead = dead_.data();
  }
  const float decay = std::exp(-std::max(0.0f, s.strain_decay) * s.dt);
  const float* P0 = P0_;
  float max_strain = 0;
#pragma omp parallel for schedule(static) num_threads(threads) reduction(max : max_strain)
  for (long p = 0; p < lm; ++p) {
    dead[p] = 0;
    int32_t a = e[2 * p], b = e[2 * p + 1];
    if (a < 0 || b < 0 || static_cast<size_t>(a) >= n || static_cast<size_t>(b) >= n || a == b)
      continue;
    float L = d.restlength[p];
    float e_end = gr_strain(gr_load3(d.P, a), gr_load3(d.P, b), L);
    float strain = e_end;
    if (!s.instantaneous_strain) {
      float e_start = gr_strain(gr_load3(P0, a), gr_load3(P0, b), L);
      float prev = d.strain ? d.strain[p] : 0.0f;
      strain = prev * decay + (e_end - e_start);
      strain = std::clamp(strain, -std::numeric_limits<float>::max(),
                          std::numeric_limits<float>::max());  // the sum may overflow
    }
    if (d.strain) d.strain[p] = strain;
    float strength = d.strength ? d.strength[p] : 1.0f;
    if (s.break_constraints && std::fabs(strain) > strength * s.break_threshold) {
      dead[p] = 1;
      continue;
    }
    max_strain = std::max(max_strain, std::fabs(strain));
  }
  if (s.remove_strands) {
    // a constraint is chain-only when both endpoints have constraint degree <= 2; removing one
    // lowers its endpoints' degrees, so repeat until a pass removes nothing
    degree_.assign(n, 0);
    auto valid = [&](long p) {
      int32_t a = e[2 * p], b = e[2 * p + 1];
      return !dead[p] && a >= 0 && b >= 0 && static_cast<size_t>(a) < n &&
             static_cast<size_t>(b) < n && a != b;
    };
    for (long p = 0; p < lm; ++p)
      if (valid(p)) {
        ++degree_[e[2 * p]];
        ++degree_[e[2 * p + 1]];
      }
    for (bool changed = true; changed;) {
      changed = false;
      for (long p = 0; p < lm; ++p) {
        if (!valid(p) || degree_[e[2 * p]] > 2 || degree_[e[2 * p + 1]] > 2) continue;
        dead[p] = 1;
        --degree_[e[2 * p]];
        --degree_[e[2 * p + 1]];
        changed = true;
      }
    }
  }
  if (stats) {
    stats->max_strain = max_strain;
    for (size_t p = 0; p < m; ++p) stats->broken += dead[p];
  }
}

// Rigid shape matching as its own constraint group (kernels/shapes.h): every grain of a
// component moves to its goal (others stay), each component is shifted out of its collider
// planes as a whole, and its friction with them is taken out of the body as a whole.
void GrainsSolver::project_shapes(const gr_grains& g, const gr_params& prm, int threads) {
  sync_planes();
  gr_grains gs = g;
  if (plane_offsets_.size() != n_ + 1) gs.plane_offsets = nullptr;
  project_components(shape_arrays(prm), gs, prm, p_.data(), comp_offsets_.size() - 1, threads);
}

// the shapes as a device projects them (opencl::ShapeArrays), into *out
const opencl::ShapeArrays* GrainsSolver::shape_arrays_there(const SubstepContext& c,
                                                            opencl::ShapeArrays* out) {
  const gr_shapes sh = shape_arrays(c.prm);
  out->offsets = sh.offsets;
  out->members = sh.members;
  out->components = comp_offsets_.size() - 1;
  out->rest = sh.rest;
  out->mass = sh.mass;
  out->generation = shape_generation_;
  out->entries = sh.collider_normal ? collider_normal_.size() : 0;
  out->collider_normal = out->entries > 0 ? collider_normal_.data() : nullptr;
  return out;
}

gr_shapes GrainsSolver::shape_arrays(const gr_params& prm) {
  gr_shapes s;
  s.offsets = comp_offsets_.data();
  s.members = comp_members_.data();
  s.rest = rest_offset_.data();
  s.mass = mass_;
  const bool friction = prm.friction_with_colliders > 0 && plane_offsets_.size() == n_ + 1 &&
                        collider_normal_.size() == plane_offsets_[n_];
  s.collider_normal = friction ? collider_normal_.data() : nullptr;
  return s;
}

GrainsSolver::DeviceSlot::DeviceSlot() = default;
GrainsSolver::DeviceSlot::~DeviceSlot() = default;
GrainsSolver::DeviceSlot::DeviceSlot(const DeviceSlot& o) {
  if (o.owner) o.owner->sync_device();
}
GrainsSolver::DeviceSlot& GrainsSolver::DeviceSlot::operator=(const DeviceSlot& o) {
  if (o.owner) o.owner->sync_device();
  device.reset();
  holds_contacts = stale = rows_stale = planes_stale = plane_rows_stale = rows_p_stale = false;
  end_there = end_P_stale = end_v_stale = false;
  hist_stale = slips_stale = slips_there = sums_there = sums_stale = friction_there = false;
  hist_planes_stale = plane_slips_stale = false;
  loaded = 0;
  owner = nullptr;
  return *this;
}
// a move brings the host's copy up to date too (the moved-from solver is still whole), so that
// no slot is stale without its owner set
GrainsSolver::DeviceSlot::DeviceSlot(DeviceSlot&& o) {
  if (o.owner) o.owner->sync_device();  // through o's device: before it moves
  device = std::move(o.device);
  holds_contacts = o.holds_contacts;
  o.holds_contacts = false;
}
GrainsSolver::DeviceSlot& GrainsSolver::DeviceSlot::operator=(DeviceSlot&& o) {
  if (o.owner) o.owner->sync_device();
  device = std::move(o.device);
  holds_contacts = o.holds_contacts;
  stale = rows_stale = planes_stale = plane_rows_stale = rows_p_stale = false;
  end_there = end_P_stale = end_v_stale = false;
  hist_stale = slips_stale = slips_there = sums_there = sums_stale = friction_there = false;
  hist_planes_stale = plane_slips_stale = false;
  loaded = 0;
  owner = nullptr;
  o.holds_contacts = false;
  return *this;
}

bool GrainsSolver::sleep_rows_on_device(const float* P, bool moved, const uint8_t* fast,
                                        std::vector<uint32_t>* out) {
  if (!candidates_on_) return false;
  const bool there = !moved && P == written_on_device_;
  // or, where the device ended the substep, the positions it wrote but for those the host moved
  const std::vector<gr_uint>* written =
      !there && !moved && finished_there_ && P == finish_P_ ? &end_changed_ : nullptr;
  if (!read_rows(!there && !written)) return false;
  out->resize(n_);
  if (!there) written_on_device_ = nullptr;  // the device's copy of them is replaced
  if (!device_.device->sleep_rows(there ? nullptr : P, radius_, fast, n_, out->data(), written))
    return false;
  if (written) written_on_device_ = P;  // patched: the written positions are there
  for (const uint32_t w : *out)
    if (w & GR_SLEEP_OVER) return false;
  ++sleep_rows_device_;
  return true;
}

opencl::Traffic GrainsSolver::device_traffic() const {
  return device_.device ? device_.device->traffic() : opencl::Traffic{};
}

bool GrainsSolver::read_rows(bool sends_positions) const {
  const size_t sent = sends_positions ? 12 * n_ : 0;
  if (device_.rows_stale && rows_read_sent_ + sent > rows_bytes_) sync_rows();
  rows_read_sent_ += sent;
  return device_.rows_stale;
}

void GrainsSolver::sync_rows() const {
  if (!device_.rows_stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  self.device_.device->fetch_rows(self.neighbors_);
  self.device_.rows_stale = false;
  ++rows_brought_;
}

void GrainsSolver::sync_history() const {
  sync_pair_history();
  sync_plane_history();
}

void GrainsSolver::sync_pair_history() const {
  if (!device_.hist_stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  self.device_.device->fetch_pair_history(self.hist_slip_.data(), &self.hist_rows_);
  self.device_.hist_stale = false;
}

void GrainsSolver::sync_plane_history() const {
  if (!device_.hist_planes_stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  // the device kept an entry a plane; the host keeps the planes that pushed (save_history)
  std::vector<uint32_t> offsets;
  std::vector<int32_t> which;
  std::vector<float> normal, slip;
  self.device_.device->fetch_plane_history(&offsets, &which, &normal, &slip);
  self.device_.hist_planes_stale = false;
  const size_t n = offsets.size() - 1;
  self.hist_plane_offsets_.assign(n + 1, 0);
  self.hist_plane_collider_.clear();
  self.hist_plane_slip_.clear();
  for (size_t i = 0; i < n; ++i) {
    for (uint32_t e = offsets[i]; e < offsets[i + 1]; ++e) {
      if (!(normal[e] > 0.0f)) continue;
      self.hist_plane_collider_.push_back(which[e]);
      self.hist_plane_slip_.insert(self.hist_plane_slip_.end(), &slip[3 * size_t(e)],
                                   &slip[3 * size_t(e)] + 3);
    }
    self.hist_plane_offsets_[i + 1] = static_cast<uint32_t>(self.hist_plane_collider_.size());
  }
}

void GrainsSolver::sync_plane_slips() const {
  if (!device_.plane_slips_stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  self.device_.device->fetch_plane_slips(self.plane_slip_.data(), self.collider_normal_.data(),
                                         collider_normal_.size());
  self.device_.plane_slips_stale = false;
}

void GrainsSolver::sync_slips() const {
  if (!device_.slips_stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  self.device_.device->fetch_pair_slips(self.pair_slip_.data(), pair_slip_.size() / 3);
  self.device_.slips_stale = false;
}

void GrainsSolver::sync_sums() const {
  if (!device_.sums_stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  self.device_.device->fetch_pair_sums(self.pair_normal_.data(), pair_normal_.size());
  self.device_.sums_stale = false;
}

void GrainsSolver::sync_planes() const {
  if (!device_.planes_stale && !device_.plane_rows_stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  const bool rows = device_.plane_rows_stale;
  self.device_.device->fetch_planes(device_.planes_stale ? &self.plane_ : nullptr,
                                    rows ? &self.plane_offsets_ : nullptr,
                                    rows ? &self.plane_collider_ : nullptr);
  self.device_.planes_stale = self.device_.plane_rows_stale = false;
}

void GrainsSolver::sync_rows_p() const {
  if (!device_.rows_p_stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  self.rows_p_.resize(3 * n_);
  self.device_.device->fetch_rows_p(self.rows_p_.data(), n_);
  self.device_.rows_p_stale = false;
}

void GrainsSolver::sync_end(bool positions, bool velocities) const {
  positions = positions && device_.end_P_stale;
  velocities = velocities && device_.end_v_stale;
  if (!positions && !velocities) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  if (!self.device_.device->fetch_end(positions ? self.end_P_.data() : nullptr,
                                      velocities ? self.end_v_.data() : nullptr, end_P_.size() / 3))
    throw std::logic_error("grains: the device no longer holds the end it kept");
  if (positions) self.device_.end_P_stale = false;
  if (velocities) self.device_.end_v_stale = false;
}

const float* GrainsSolver::end_positions() {
  sync_end(true, false);
  return end_P_.data();
}

const float* GrainsSolver::end_velocities() {
  sync_end(false, true);
  return end_v_.data();
}

void GrainsSolver::sync_device() const {
  sync_end(true, true);
  sync_rows();
  sync_history();
  sync_slips();
  sync_plane_slips();
  sync_sums();
  sync_rows_p();
  sync_planes();
  sync_contacts();
}

void GrainsSolver::substep(GrainsData& d, const GrainsSettings& s, const ColliderState* colliders,
                           size_t collider_count, GrainsStats* stats) {
  if (stats) *stats = GrainsStats{};
  candidates_on_ = false;
  p_on_device_ = planes_on_device_ = predicted_there_ = searched_there_ = p_made_ = false;
  plane_rows_there_ = planes_same_ = planes_kept_there_ = false;
  written_on_device_ = nullptr;
  finished_there_ = collided_there_ = carried_ = carried_from_ = end_stays_ = false;
  stable_there_ = stabilized_ = false;
  stabilize_passes_ = 0;
  device_.owner = this;
  // the last substep's carried slips and pair sums are done with (its saved slips stay)
  device_.slips_stale = device_.slips_there = device_.sums_there = device_.sums_stale = false;
  device_.plane_slips_stale = false;
  device_.friction_there = device_.p_there = false;
  slept_there_ = sleep_there_;
  sleep_there_ = sleep_changed_ = force_there_ = false;
  // a start held on the device: the end the last substep left there (GrainsData::start_held)
  start_held_ = d.start_held;
  if (start_held_ && !(device_.end_there && d.n == n_))
    throw std::logic_error("grains: a substep starts from an end the device does not hold");
  device_.end_there = false;
  // the device's calls of this substep may share the arrays bind_inputs makes, which hold their
  // values until the next
  if (device_.device) device_.device->begin_substep();
  if (d.n == 0) return;
  if (!(collider_count > 0 && colliders)) collider_count = 0;
  gr_grains g;
  std::memset(&g, 0, sizeof g);
  gr_params prm = make_params(s);
  gr_normal_sums acc{nullptr, nullptr, nullptr, nullptr, nullptr};
  SubstepContext c(d, s, colliders, collider_count, g, prm, acc);
  c.threads = s.threads > 0 ? s.threads : omp_get_max_threads();
  c.iterations = std::max(0, s.constraint_iterations);

  // the kernels' inputs: per-grain arrays, pins, shapes, explicit constraints
  bind_inputs(c);
  c.jacobi_there = jacobi_on_device(c);

  // use_opencl: the start positions and velocities from the last substep's end on the device
  carry_start(c);
  // the grains node's sleeping test, on the device (GrainsData::sleep)
  if (d.sleep) sleep_begin(c);

  // 1. predict
  predict(c);
  open_sums(c);

  // 2. neighbour candidates and collider planes from the predicted positions
  open_search(c);
  if (c.pairs_on) find_pairs(c, true);
  candidates_on_ = c.pairs_on;
  c.rebuilds_there = rebuilds_there(c);
  if (c.colliders_on) update_planes(c, true);
  // contact history (load_history): each contact's slip left from earlier substeps
  const bool history = (c.pair_friction_pass || c.collider_friction_pass) &&
                       s.contact_solver != kContactGaussSeidel;
  if (history) {
    load_history(d, c.pair_friction_pass, c.collider_friction_pass, c.same_rows, c.threads,
                 s.use_opencl && !s.host_history ? &c : nullptr);
    if (c.pair_friction_pass) g.pair_slip = pair_slip_.data();
    if (c.collider_friction_pass) g.plane_slip = plane_slip_.data();
  }

  // pre-stabilization (gr_stabilize): the overlaps present at the start of the substep are
  // removed from the start and predicted positions alike, without velocity
  // (no iterations: no pass, nothing moved)
  if (s.pre_stabilization && s.contact_solver != kContactGaussSeidel && c.iterations > 0 &&
      ((c.pairs_on && s.internal_collisions_weight > 0) || c.colliders_on)) {
    pre_stabilize(g, prm, s.internal_collisions_weight > 0, c.iterations, c.threads,
                  s.use_opencl ? &c : nullptr);
    stabilized_ = true;
    g.P = P_stable_.data();  // on the device alone where it stayed there (stable_there_)
  }

  // 3. Jacobi iterations, friction, pins; or the contacts one at a time (gauss_seidel.cpp)
  if (s.contact_solver == kContactGaussSeidel) {
    gauss_seidel(c);
  } else {
    seq_loads_.clear();
    seq_table_.clear();
    seq_valid_ = false;
    device_.stale = false;
    iterate(c);
  }

  // 4. velocity, drift, final collisions; write P and v (and the impact data)
  write_back(d, s, g, prm, colliders, collider_count, c.origin, c.impacts_here, c.threads);

  if (history)
    save_history(d, s, g, prm, p_.data(), c.pair_friction_pass, c.collider_friction_pass, c.threads,
                 s.use_opencl && !s.host_history ? &c : nullptr);
  else
    hist_id_.clear(), hist_slip_.clear(), device_.hist_stale = device_.hist_planes_stale = false;

  // 5. strain, breaking, strands
  if (c.constraints_on) update_constraints(d, s, c.threads, stats);
  if (start_held_) ++held_starts_;  // and no stage brought its start here

  // stats: serial, in a fixed order
  if (stats && c.pairs_on) contact_stats(d, stats);
}

// The substep's coordinates (world positions minus c.origin, local_origin: 0 near the origin)
// and what the kernels read there (c.g, c.prm): start positions, radius, mass, inverse mass (or
// 1/shockmass), attributes, pins, rigid shapes and explicit constraints; the caller's arrays
// where they serve as they are, copies otherwise (freed when no longer needed).
void GrainsSolver::bind_inputs(SubstepContext& c) {
  GrainsData& d = c.d;
  const GrainsSettings& s = c.s;
  gr_grains& g = c.g;
  gr_params& prm = c.prm;
  const int threads = c.threads;
  const size_t n = d.n;
  const long ln = static_cast<long>(n);
  // a start held on the device stays there where every stage takes it there; its origin is the
  // one its box, measured there, gives
  if (start_held_ && !start_stays(d, s, c.colliders, c.collider_count)) fetch_start(c);
  const Vec3 origin = start_held_ ? end_origin_ : local_origin(d.P, n, threads);
  c.origin = origin;
  const bool shifted = !(origin.x == 0 && origin.y == 0 && origin.z == 0);
  prm.shock_origin_x -= origin.x;
  prm.shock_origin_y -= origin.y;
  prm.shock_origin_z -= origin.z;

  // explicit constraints: weight 0 skips them entirely (no adjacency, no strain, no breaking)
  c.constraints_on =
      s.explicit_constraints_weight > 0 && d.prim_count > 0 && d.prim_points && d.restlength;
  n_ = n;
  inv_mass_.resize(n);
  auto drop = [](std::vector<float>& v) {
    if (v.capacity()) std::vector<float>().swap(v);
  };
  if (shifted || c.constraints_on) {
    P0_copy_.resize(3 * n);
    if (!start_held_) {
#pragma omp parallel for schedule(static) num_threads(threads)
      for (long i = 0; i < ln; ++i) store3(P0_copy_.data(), i, load3(d.P, i) - origin);
    }
    P0_ = P0_copy_.data();
  } else {
    drop(P0_copy_);
    P0_ = d.P;  // minus an origin of 0: the same floats
  }
  if (d.pscale) {
    drop(radius_copy_);
    radius_ = d.pscale;
  } else {
    radius_copy_.assign(n, 0.5f * s.particle_separation);
    radius_ = radius_copy_.data();
  }
  if (d.mass) {
    drop(mass_copy_);
    mass_ = d.mass;
  } else {
    mass_copy_.assign(n, 1.0f);
    mass_ = mass_copy_.data();
  }
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long i = 0; i < ln; ++i) {
    const float m = mass_[i];
    if (s.mass_shock() == MassShock::Global) {
      // written "prior to iterating" (help page), from the start-of-substep position
      float sm = gr_shockmass(&prm, m, gr_load3(P0_, static_cast<int>(i)));
      if (d.shockmass) d.shockmass[i] = sm;
      inv_mass_[i] = sm > 0 ? 1.0f / sm : 0.0f;
    } else {
      inv_mass_[i] = m > 0 ? 1.0f / m : 0.0f;
    }
  }

  // pairs are needed for contacts or clumping; weight 0 for both skips neighbour search and the
  // pair loop entirely
  c.pairs_on = s.internal_collisions_weight > 0 || s.clumping_weight > 0;
  c.colliders_on = c.collider_count > 0;

  g.P = P0_;
  g.v = d.v;
  g.force = d.force;
  g.force_index = d.force_index;
  g.mass = mass_;
  g.radius = radius_;
  g.inv_mass = inv_mass_.data();
  {
    // equal grains: the contact loop's fast path reads neither radius nor inverse mass
    const float r0 = radius_[0], w0 = inv_mass_[0];
    bool uniform = r0 > 0 && w0 > 0 && std::isfinite(r0) && std::isfinite(w0);
    for (size_t i = 1; uniform && i < n; ++i) uniform = radius_[i] == r0 && inv_mass_[i] == w0;
    g.uniform_radius = uniform ? r0 : 0.0f;
    g.uniform_inv_mass = uniform ? w0 : 0.0f;
  }
  g.friction = d.friction;
  g.repulsionweight = d.repulsionweight;
  g.repulsionstiffness = d.repulsionstiffness;
  g.attractionweight = d.attractionweight;
  g.attractionstiffness = d.attractionstiffness;
  // pins: off (costs nothing) without targetstiffness or with weight or stiffness 0
  if (d.targetstiffness && d.targetP && s.target_weight > 0 && s.target_stiffness > 0) {
    g.targetP = d.targetP;
    if (shifted) {
      target_local_.resize(3 * n);
#pragma omp parallel for schedule(static) num_threads(threads)
      for (long i = 0; i < ln; ++i) store3(target_local_.data(), i, load3(d.targetP, i) - origin);
      g.targetP = target_local_.data();
    }
    g.targetweight = d.targetweight;
    g.targetstiffness = d.targetstiffness;
  }

  // rigid shape matching: its components and rest shapes (build_shapes)
  c.shapes_on = s.enable_rigid_shape_matching && d.prim_points && d.prim_count > 0;
  if (c.shapes_on) build_shapes(d);
  // (with jacobi where its iterations are one device call, rebuilds and all: jacobi_whole)
  c.shapes_here =
      c.shapes_on &&
      !(s.use_opencl && !s.host_shapes &&
        (s.contact_solver == kContactGaussSeidel || jacobi_loop_there(s, rebuilds_fit(c))) &&
        open_device().shapes_there());

  // explicit constraints (c.constraints_on above)
  if (c.constraints_on) {
    build_constraints(d);
    g.con_offsets = con_offsets_.data();
    g.con_other = con_other_.data();
    g.con_prim = con_prim_.data();
    g.restlength = d.restlength;
    g.constraintweight = d.constraintweight;
    g.constraintstiffness = d.constraintstiffness;
  }
}

// The last substep's end on the device (SubstepEnd) left its written positions and
// velocities there, and end_P_ and end_v_ hold the same floats here. Where the grains node hands
// back the same (nothing between the substeps moved them: the same grains in the same order, no
// sleeper put back, no other node's change), the device makes this substep's start from them
// (the world positions less this substep's origin, the subtraction bind_inputs makes) and only
// the grains that differ go up, instead of every grain's start position and velocity (24 bytes
// a grain). Exact: a grain is taken from there only when its host floats are the ones the device
// holds, so the substep is the same bits either way. Grains in another order (a frame's first
// substep, whose grains the node sorts again by cell), or born or killed since, are found in
// the end by their ids, and each grain's index there goes up (4 bytes a grain). Not past a
// quarter of the grains differing: their 28 bytes each would cost more than sending all.
void GrainsSolver::carry_start(const SubstepContext& c) {
  const GrainsSettings& s = c.s;
  const size_t n = n_;
  const float origin[3] = {c.origin.x, c.origin.y, c.origin.z};
  if (start_held_) {  // every grain is what the end there wrote (start_stays)
    carry_changed_.clear();
    carried_ = device_.device->carry_start(P0_, c.d.v, n, origin, carry_changed_);
    if (!carried_) throw std::logic_error("grains: the device holds no end to start from");
    return;
  }
  if (!s.use_opencl || s.resend_start || !device_.device || end_P_.empty()) return;
  const size_t m = end_P_.size() / 3;  // the last end's grains
  // in the end's order (the same ids, or as many grains where either has no ids), or found in
  // it by id (carry_from_: a frame's first substep, whose grains the node sorts again by cell,
  // or grains born or killed since)
  const bool by_id = c.d.id && end_ids_.size() == m;
  const bool same = by_id ? m == n && std::equal(end_ids_.begin(), end_ids_.end(), c.d.id) : m == n;
  if (!same && !by_id) return;
  if (!same) find_in_end(c.d.id, n);
  sync_end(true, true);  // an end held there that its holder did not take up
  const float* v = end_v_.size() == 3 * m ? c.d.v : nullptr;
  const long ln = static_cast<long>(n);
  carry_differs_.resize(n);
  const float* P = c.d.P;
  const gr_uint* from = same ? nullptr : carry_from_.data();
#pragma omp parallel for schedule(static) num_threads(c.threads)
  for (long i = 0; i < ln; ++i) {
    const gr_uint j = from ? from[i] : static_cast<gr_uint>(i);
    const size_t at = 3 * size_t(i), end_at = 3 * size_t(j);
    carry_differs_[i] = j == kNotInEnd ||
                        std::memcmp(P + at, &end_P_[end_at], 3 * sizeof(float)) != 0 ||
                        (v && std::memcmp(v + at, &end_v_[end_at], 3 * sizeof(float)) != 0);
  }
  carry_changed_.clear();
  for (size_t i = 0; i < n && carry_changed_.size() <= n / 4; ++i)
    if (carry_differs_[i]) carry_changed_.push_back(static_cast<gr_uint>(i));
  if (carry_changed_.size() > n / 4) return;
  carried_ =
      device_.device->carry_start(P0_, v, n, origin, carry_changed_, from ? &carry_from_ : nullptr);
  carried_from_ = carried_ && from;
}

// carry_from_: each of the n grains' index in the last end, found by its id (kNotInEnd: none);
// through a table over the ids' range where it is at most 4 times the grains, else by sorting
void GrainsSolver::find_in_end(const int32_t* id, size_t n) {
  const size_t m = end_ids_.size();
  carry_from_.assign(n, kNotInEnd);
  const auto [lo, hi] = std::minmax_element(end_ids_.begin(), end_ids_.end());
  const int64_t first = *lo, span = int64_t(*hi) - first + 1;
  if (span <= 4 * int64_t(std::max(m, n))) {
    std::vector<gr_uint>& at = carry_at_;
    at.assign(static_cast<size_t>(span), kNotInEnd);
    for (size_t j = 0; j < m; ++j) at[size_t(end_ids_[j] - first)] = static_cast<gr_uint>(j);
    for (size_t i = 0; i < n; ++i) {
      const int64_t k = int64_t(id[i]) - first;
      if (k >= 0 && k < span) carry_from_[i] = at[size_t(k)];
    }
    return;
  }
  std::vector<std::pair<int32_t, gr_uint>> sorted(m);
  for (size_t j = 0; j < m; ++j) sorted[j] = {end_ids_[j], static_cast<gr_uint>(j)};
  std::sort(sorted.begin(), sorted.end());
  for (size_t i = 0; i < n; ++i) {
    auto it = std::lower_bound(sorted.begin(), sorted.end(), std::pair<int32_t, gr_uint>{id[i], 0});
    if (it != sorted.end() && it->first == id[i]) carry_from_[i] = it->second;
  }
}

// whether chebyshev_rho steps the Jacobi iterations (more of them than the plain Jacobi ones that
// start each substep: kernels/iterate.h)
static bool chebyshev_steps(const GrainsSettings& s) {
  return s.chebyshev_rho > 0 && s.constraint_iterations > GR_CHEBYSHEV_DELAY;
}

// whether the settings find rows or planes again during the Jacobi iterations
static bool finds_again(const GrainsSettings& s) {
  return s.update_neighbors_during_iterations || s.update_collisions_during_iterations;
}

// the settings under which a Jacobi substep's stages chain on the device (jacobi_on_device: no
// history made here, none of the test switches that keep a stage here, no rebuild during the
// iterations but where `rebuilds` says they are made there too); the substep's grains decide
// the rest
static bool jacobi_chain(const GrainsSettings& s, bool rebuilds = false) {
  return s.contact_solver != kContactGaussSeidel && !(chebyshev_steps(s) && s.host_chebyshev) &&
         (rebuilds || !finds_again(s)) && !s.host_history && !s.send_history_p && !s.host_predict &&
         !s.host_finish;
}

// gauss_seidel's, and jacobi's where its substep chains on the device (jacobi_chain: its end
// there, which the test's end follows there; with rebuilds during the iterations where they
// are made there, rebuilds_chain)
bool GrainsSolver::sleeps_on_device(const GrainsSettings& s, const ColliderState* colliders,
                                    size_t collider_count) {
  if (!s.use_opencl ||
      (s.contact_solver != kContactGaussSeidel && !jacobi_chain(s, rebuilds_chain(s))) ||
      s.host_finish || s.mass_shock() == MassShock::Global ||
      meshes_here(s, colliders, collider_count))
    return false;
  opencl::Iterations& device = open_device();
  return device.builds_contacts() && device.sleeps_there();
}

bool GrainsSolver::motion_on_device(double step, double fps, double* worst, double* fall) {
  if (!device_.end_there || !device_.device ||
      !device_.device->motion(n_, force_there_, force_uniform_, sleep_there_, step, fps, worst,
                              fall))
    return false;
  ++motions_device_;
  return true;
}

void GrainsSolver::fetch_sleep_state(float* time, float* anchor, float* accel, int32_t* contacts) {
  const size_t n = sleep_state_n_;
  auto back = [n](auto* to, auto& kept, size_t width) {
    const bool need = to && kept.empty();
    if (need) kept.resize(width * n);
    return need ? kept.data() : nullptr;
  };
  float* t = back(time, sleep_back_time_, 1);
  float* an = back(anchor, sleep_back_anchor_, 3);
  float* ac = back(accel, sleep_back_accel_, 3);
  int32_t* co = back(contacts, sleep_back_contacts_, 1);
  if ((t || an || ac || co) && !(device_.device && device_.device->fetch_sleep(t, an, ac, co, n)))
    throw std::logic_error("grains: the device no longer holds the sleeping test's state");
  if (time) std::copy(sleep_back_time_.begin(), sleep_back_time_.end(), time);
  if (anchor) std::copy(sleep_back_anchor_.begin(), sleep_back_anchor_.end(), anchor);
  if (accel) std::copy(sleep_back_accel_.begin(), sleep_back_accel_.end(), accel);
  if (contacts) std::copy(sleep_back_contacts_.begin(), sleep_back_contacts_.end(), contacts);
}

// Whether the device carries the state it holds into this substep (Iterations::sleep_carry)
// instead of taking up the node's (z): where the last substep's test was made there and its
// state came back whole since (the node's hold fetched), and the node's state is that, grain
// for grain through the order carry_start carried (bit for bit: nothing wrote the attributes
// since). A frame's first substep, whose grains the node sorts again after the frame's
// output read them, then sends nothing for the test (32 bytes a grain before).
bool GrainsSolver::carry_sleep(const GrainsSleep& z) {
  const size_t m = sleep_state_n_, n = n_;
  if (!slept_there_ || !carried_ || sleep_back_time_.size() != m ||
      sleep_back_anchor_.size() != 3 * m || sleep_back_accel_.size() != 3 * m ||
      sleep_back_contacts_.size() != m || (!carried_from_ && m != n))
    return false;
  const gr_uint* from = carried_from_ ? carry_from_.data() : nullptr;
  const size_t f3 = 3 * sizeof(float);
  for (size_t i = 0; i < n; ++i) {
    const size_t j = from ? from[i] : i;
    if (j >= m || std::memcmp(&z.time[i], &sleep_back_time_[j], sizeof(float)) != 0 ||
        std::memcmp(&z.anchor[3 * i], &sleep_back_anchor_[3 * j], f3) != 0 ||
        std::memcmp(&z.accel[3 * i], &sleep_back_accel_[3 * j], f3) != 0 ||
        z.contacts[i] != sleep_back_contacts_[j])
      return false;
  }
  return open_device().sleep_carry(n);
}

// The grains node's sleeping test begun on the device (kernels/sleep.h): each grain's start
// (what the last end there wrote, for a start held there; else d.P, sent) and velocity kept, a
// sleeper made a fixed grain in the arrays the substep reads there. The host's inverse masses
// stay the awake grains': the contact loop's equal-grains path is off, and gauss_seidel's list
// is built again where a grain's sleep changed (seq_list_kept).
void GrainsSolver::sleep_begin(SubstepContext& c) {
  const GrainsSleep& z = *c.d.sleep;
  bool uniform = false;
  const float* force = device_force(c.g, &uniform);
  opencl::Iterations::SleepState state;
  state.time = z.time, state.anchor = z.anchor, state.accel = z.accel, state.contacts = z.contacts;
  bool changed = true;
  const bool carried = z.time && carry_sleep(z);
  if (carried) ++sleep_carried_;
  // the start as the last end there wrote it: held there, or every grain carried from it
  // (carry_start: none differs, each found there), whose world positions are the host's (12
  // bytes a grain less)
  const bool start_there = start_held_ || (carried_ && carry_changed_.empty());
  if (!open_device().sleep_begin(c.g, z.params, n_, start_there ? nullptr : c.d.P, z.can, force,
                                 uniform, z.time && !carried ? &state : nullptr, &changed))
    throw std::logic_error("grains: the device cannot begin the sleeping test it was given");
  sleep_there_ = true;
  sleep_changed_ = changed || !slept_there_;
  sleep_params_ = z.params;
  sleep_state_n_ = n_;
  c.g.uniform_inv_mass = 0.0f;
  ++slept_device_;
}

// A start held on the device (GrainsData::start_held) stays there where no stage reads the start
// here: the device predicts (GrainsSolver::predict), finds the planes (no mesh collider) and
// solves; no global mass shock, constraint or shape reads the start positions. A kept start
// velocity (error control's stabilizing substep) is the device's too: its end writes the one it
// holds (SubstepEnd::keep_velocity). A stage that reads the start anyway (the
// host's search of rows, host_p) brings it then.
bool GrainsSolver::start_stays(const GrainsData& d, const GrainsSettings& s,
                               const ColliderState* colliders, size_t collider_count) {
  // jacobi's: where its chain runs there (jacobi_chain, rebuilds_chain; the shapes need
  // primitives, the impact data keep the end here)
  return s.use_opencl &&
         (s.contact_solver == kContactGaussSeidel || jacobi_chain(s, rebuilds_chain(s))) &&
         !s.resend_start && s.mass_shock() != MassShock::Global && d.prim_count == 0 &&
         !meshes_here(s, colliders, collider_count);
}

// the held start into d.P and d.v (world) and, once bind_inputs has set it, P0_ (the substep's
// coordinates); the device's own start, made from the same floats, stays as it is
void GrainsSolver::fetch_start(const SubstepContext& c) {
  const size_t n = n_;
  sync_end(true, true);
  std::copy_n(end_P_.data(), 3 * n, c.d.P);
  std::copy_n(end_v_.data(), 3 * n, c.d.v);
  if (P0_ == P0_copy_.data() && P0_copy_.size() == 3 * n) {
    const long ln = static_cast<long>(n);
#pragma omp parallel for schedule(static) num_threads(c.threads)
    for (long i = 0; i < ln; ++i) store3(P0_copy_.data(), i, load3(c.d.P, i) - c.origin);
  }
  start_held_ = false;
}

// step 1: each grain's predicted position p_ (gr_predict). With use_opencl and gauss_seidel the
// device makes the same floats (gr_fmadd: fused on both) from the start, velocities, masses and
// force it holds, which then need not go up: the search of rows or planes and the solve take
// them there, and the Verlet test that keeps the rows is made there (keep_rows). The host makes
// them too only where a stage reads them here (host_p): the planes it finds itself (a mesh
// collider's), its own search of rows where the device's declines, a contact list it builds.
void GrainsSolver::predict(SubstepContext& c) {
  const size_t n = n_;
  // one float past the last grain: the contact loop loads positions 4 floats at a time
  p_.resize(3 * n + 1);
  p_next_.resize(3 * n + 1);
  if (c.s.use_opencl && (c.s.contact_solver == kContactGaussSeidel || c.jacobi_there)) {
    c.device_force = device_force(c.g, &c.force_uniform);
    force_there_ = c.device_force != nullptr;
    force_uniform_ = c.force_uniform;
    if (force_there_ && force_uniform_) std::copy_n(c.device_force, 3, force_row_);
    if (!c.s.host_predict) {
      open_device().predict(c.g, c.prm, n, c.device_force, c.force_uniform);
      predicted_there_ = p_on_device_ = true;
      return;
    }
  }
  host_p(c);
}

float* GrainsSolver::host_p(const SubstepContext& c) {
  if (p_made_) return p_.data();
  if (stable_there_)
    throw std::logic_error(
        "grains: the prediction pre-stabilization moved on the device is not here");
  if (start_held_) fetch_start(c);  // its start, here
  const long ln = static_cast<long>(n_);
#pragma omp parallel for schedule(static) num_threads(c.threads)
  for (long i = 0; i < ln; ++i) gr_predict(&c.g, &c.prm, p_.data(), static_cast<int>(i));
  p_made_ = true;
  ++host_predictions_;
  return p_.data();
}

// Which friction passes run, and the sums the iterations keep for them and the impact data
// (c.acc). Friction (gr_friction_pass): once after the loop, or after every iteration with
// accurate friction, bounded by the normal corrections each contact applied, summed over the
// iterations. gauss_seidel's contacts carry their own friction and loads (kernels/sequential.h)
// and read none of the pairs' sums nor the per-iteration ones; the collider planes' sums serve
// rigid shapes' friction with the colliders in either solver (project_shapes).
void GrainsSolver::open_sums(SubstepContext& c) {
  const GrainsSettings& s = c.s;
  const size_t n = n_;
  const bool jacobi = s.contact_solver != kContactGaussSeidel;
  c.pair_friction_pass =
      jacobi && c.pairs_on && s.internal_collisions_weight > 0 && s.friction_with_particles > 0;
  c.collider_friction_pass = c.colliders_on && s.friction_with_colliders > 0;
  if (jacobi && s.accurate_friction && (c.pair_friction_pass || c.collider_friction_pass)) {
    friction_dx_.assign(3 * n, 0.0f);
    c.acc.friction_dx = friction_dx_.data();
  }
  c.impacts = c.d.impact_impulse && c.colliders_on;
  // the device makes them at its end where it finds the planes (meshes_here: none) and ends the
  // substep: gauss_seidel's (not with rigid shapes projected here), jacobi's chain;
  // update_planes() and iterate() take them back here where it does not after all
  c.impacts_here = c.impacts && !(s.use_opencl && !s.host_finish && !c.shapes_here &&
                                  (s.contact_solver == kContactGaussSeidel || c.jacobi_there) &&
                                  !meshes_here(s, c.colliders, c.collider_count));
  if (c.impacts) {
    collider_dx_.assign(3 * GR_MAX_PLANES * n, 0.0f);
    c.acc.collider_dx = collider_dx_.data();
  }
}

// The neighbour search's settings (c.q, c.search_radius) and whether its rows may be kept
// across substeps (c.reusable).
void GrainsSolver::open_search(SubstepContext& c) {
  const GrainsSettings& s = c.s;
  const size_t n = n_;
  // assume_uniform_radius: one grid cell size and every grain searched as the largest one, a
  // superset of the true candidates. With equal radii that is the same set, found faster; with
  // mixed radii small grains gather farther candidates and max_neighbors fills with them, so the
  // toggle is for scenes whose grains share one size (help page "Assume Uniform Radius").
  c.search_radius = radius_;
  if (s.assume_uniform_radius && !(c.g.uniform_radius > 0)) {  // equal radii need no copy
    float r_max = 0;
    for (size_t i = 0; i < n; ++i) r_max = std::max(r_max, radius_[i]);
    search_radius_.assign(n, r_max);
    c.search_radius = search_radius_.data();
  }
  c.q.query_scale = s.neighbor_query_scale;
  c.q.max_neighbors = s.max_neighbors;
  c.q.uniform_radius = s.assume_uniform_radius;
  c.q.threads = c.threads;
  // Verlet reuse (keep_rows): the rows of the last substep still hold every pair that can touch
  // in this one when the grains are the same, in the same order, and none has moved more than
  // a quarter of the rows' skin since they were built (see rows_skin_)
  c.reusable =
      !(s.clumping_weight > 0) && !c.constraints_on && !s.update_neighbors_during_iterations;
}

bool GrainsSolver::keep_rows(const SubstepContext& c) {
  const size_t n = n_;
  const GrainsSettings& s = c.s;
  if (!c.reusable || !rows_valid_ || rows_ids_.size() != n || !(rows_skin_ > 0)) return false;
  if (rows_query_scale_ != s.neighbor_query_scale || rows_max_ != s.max_neighbors ||
      rows_uniform_ != s.assume_uniform_radius)
    return false;
  for (size_t i = 0; i < n; ++i)
    if (rows_ids_[i] != grain_id(c.d, i) || rows_radius_[i] != radius_[i]) return false;
  // on the device where both the rows' positions and this substep's prediction are there (the
  // same float: gr_rows_moved, unfused on both sides, and a largest in any order)
  float moved2 = 0;
  if (device_.rows_p_stale && predicted_there_ && device_.device->rows_moved(n, &moved2)) {
    ++rows_tests_device_;
  } else {
    sync_rows_p();
    moved2 = rows_moved2(host_p(c), rows_p_.data(), n, c.threads);
  }
  return std::sqrt(moved2) < 0.25f * rows_skin_;
}

// The rows (their offsets and indices) stay on the device (find_pairs) when nothing in the
// substep reads them on the host: gauss_seidel builds its contact list there (not with impact
// data or rigid shapes made here, whose lists the host builds; gauss_seidel.cpp brings the rows
// when the device's build declines), and clumping's Jacobi group takes the host's rows; jacobi's
// passes and its contact history read them there (load_history and save_history bring them where
// the host makes the history). Neither keeps them with constrained pairs to drop. Error control's
// overlap statistics, the Verlet skin and the rows' longest are then reduced there
// (contact_stats, remember_rows, find_pairs); a rebuild during the iterations, the grains node's
// sleeping test, a saved state and a copy of the solver bring them (sync_rows).
bool GrainsSolver::rows_stay(const SubstepContext& c) const {
  const GrainsSettings& s = c.s;
  if (!s.use_opencl || s.fetch_rows ||
      (c.constraints_on && !s.collide_mutually_constrained_particles))
    return false;
  if (s.contact_solver != kContactGaussSeidel) return !s.host_history;
  return !c.impacts_here && !c.shapes_here && !(s.clumping_weight > 0);
}

void GrainsSolver::find_pairs(SubstepContext& c, bool first) {
  const size_t n = n_;
  const long ln = static_cast<long>(n);
  const int threads = c.threads;
  gr_grains& g = c.g;
  // a rebuild during the device's iterations (rebuilds_there): the rows stay there, and what
  // the iterations summed follows them there
  const bool resident = !first && c.rebuilds_there;
  // ... and the first search of a substep chained there whose rows are found again there
  // (jacobi_on_device): its rows stay there whatever reads them later
  const bool chained = first && c.jacobi_there && c.s.update_neighbors_during_iterations;
  if (!first && c.pair_friction_pass && !resident) {
    sync_rows();  // the sums and slips are carried over to the rebuilt rows here
    std::swap(prev_neighbors_, neighbors_);
  }
  // The friction pass's per-entry sums and the search's list store are about the same size
  // and never needed at once, so the search keeps its lists in pair_normal_'s memory, which
  // then takes the sums (the lists are copied out by then). Rebuilds during the iterations
  // carry the sums over and use the search's own store.
  // use_opencl: the rows stay on the device when the substep reads them only there (their
  // number of entries comes back)
  const bool stay = resident || chained ||
                    (first && rows_stay(c) && open_device().builds_contacts() &&
                     !(rows_read_sent_ > rows_bytes_));
  if (first && keep_rows(c)) {
    c.same_rows = true;
  } else {
    // the contact history's lookup reads last substep's rows: those the host's save read, or
    // the device's copy where they stayed there (sync_history)
    if (first && c.pair_friction_pass && !hist_slip_.empty() && !device_.rows_stale)
      hist_rows_ = neighbors_;
    // use_opencl: the rows found on the device (the same rows; the host's search where the
    // device cannot, opencl/iterations.h)
    // (a rebuild there: the iterate there, as run() offers it)
    const bool p_there = (first && predicted_there_) || resident;
    const bool on_device =
        c.s.use_opencl && open_device().find_neighbours(p_for_device(c, p_there), c.search_radius,
                                                        n, c.q, neighbors_, stay, p_there);
    if (!on_device && (resident || chained))
      throw std::runtime_error(
          "use_opencl: the device could not find the neighbour rows again during the iterations "
          "(update_neighbors_during_iterations; too many for its largest buffer?); run it with "
          "use_opencl off");
    if (!on_device)
      search_.find(host_p(c), c.search_radius, n, c.q, neighbors_,
                   first && c.pair_friction_pass ? &pair_normal_ : nullptr);
    rows_on_device_ = on_device;
    searched_there_ = first && on_device;
    p_on_device_ = first && (on_device || predicted_there_);
    rows_true_radius_ = c.search_radius == radius_;
    device_.rows_stale = on_device && stay;
    rows_left_ += device_.rows_stale;
    if (first) {
      ++rows_searched_;
      rows_read_sent_ = 0, rows_bytes_ = 4 * (n + 1 + size_t(neighbors_.offsets.back()));
    }
    rows_valid_ = device_.rows_p_stale = longest_known_ = false;
    // the positions the rows were built from: the device's where its search took them
    if (first && c.reusable)
      remember_rows(c.d, c.s, c.search_radius, on_device && predicted_there_ ? nullptr : host_p(c),
                    threads);
  }
  if (!stay) sync_rows();  // the host reads them below or later in the substep
  // mutually constrained grains that do not collide: drop their pairs once here rather than
  // look each one up in every iteration; rows keep their order and their max_neighbors cut
  if (c.constraints_on && !c.s.collide_mutually_constrained_particles) {
    rows_on_device_ = false;  // the device's rows keep them
    drop_constrained_pairs(threads);
    g.nbr_unconstrained = 1;
  }
  g.nbr_offsets = neighbors_.offsets.data();
  g.nbr_indices = device_.rows_stale ? nullptr : neighbors_.indices.data();
  if (!c.pair_friction_pass) return;
  const size_t entries = neighbors_.offsets.back();
  // the longest row, measured where the rows are, once for rows kept across substeps
  if (!(first && c.same_rows && longest_known_)) {
    rows_longest_ = 0;
    if (!(device_.rows_stale && device_.device->row_longest(n, &rows_longest_))) {
      sync_rows();
      for (size_t i = 0; i < n; ++i)
        rows_longest_ = std::max<size_t>(rows_longest_, neighbors_.count(i));
    }
    longest_known_ = true;
  }
  const size_t longest = rows_longest_;
  // whole blocks of the contact loop's lanes (gr_gather_contacts_lanes)
  row_length_ = (std::max<size_t>(longest, 1) + GR_LANES - 1) / GR_LANES * GR_LANES;
  // each thread's row a whole number of cache lines apart from the next one's, plus a line:
  // threads writing one line between them every grain would pass it back and forth
  row_stride_ = (row_length_ + 15) / 16 * 16 + 16;
  pair_normal_it_.resize(row_stride_ * size_t(threads));
  if (first) {
    pair_normal_.assign(entries, 0u);  // the bits of 0.0f
  } else if (resident) {
    // carried there (Iterations::carry_pairs): the host's arrays sized for the new rows, their
    // contents the device's
    resize_for_rewrite(pair_normal_, entries);
    resize_for_rewrite(pair_slip_, 3 * entries);
    open_device().carry_pairs(n, entries, g.pair_slip != nullptr);
    device_.sums_there = device_.sums_stale = true;
    if (g.pair_slip) device_.slips_there = device_.slips_stale = true;
    g.pair_slip = g.pair_slip ? pair_slip_.data() : nullptr;
  } else {
    // carry each pair's accumulated overlap over to its slot in the rebuilt rows
    std::vector<uint32_t> old;
    sync_sums();  // the device's, where they stayed
    device_.sums_there = false;
    old.swap(pair_normal_);
    pair_normal_.assign(entries, 0u);
    std::vector<float> old_slip;
    sync_slips();  // the device's, where it made them
    device_.slips_there = false;
    old_slip.swap(pair_slip_);
    pair_slip_.assign(3 * entries, 0.0f);
    const float* was_slip = old_slip.empty() ? nullptr : old_slip.data();
#pragma omp parallel for schedule(static) num_threads(threads)
    for (long i = 0; i < ln; ++i)
      gr_carry_pair_row(prev_neighbors_.offsets.data(), prev_neighbors_.indices.data(), old.data(),
                        was_slip, neighbors_.offsets.data(), neighbors_.indices.data(),
                        pair_normal_.data(), was_slip ? pair_slip_.data() : nullptr,
                        static_cast<int>(i));
    g.pair_slip = pair_slip_.data();
  }
  c.acc.pair_iteration = pair_normal_it_.data();
  c.acc.pair = pair_normal_.data();
}

// Collider planes. What the iterations accumulate per plane follows its collider through a
// rebuild during the iterations, not its place in the nearest-first row (two planes swap when
// the iterations push a grain nearer the second): the friction pass's sums, per plane entry,
// and the impact data's applied corrections, per slot. A collider the rebuilt row no longer
// holds takes its sums with it.
void GrainsSolver::update_planes(SubstepContext& c, bool first) {
  const size_t n = n_;
  const long ln = static_cast<long>(n);
  gr_grains& g = c.g;
  const bool friction = c.collider_friction_pass;
  const bool carry = !first && (friction || c.impacts);
  // a rebuild during the device's iterations (rebuilds_there): the planes stay there, and what
  // the iterations summed follows them there
  const bool resident = !first && c.rebuilds_there;
  std::vector<float> old_slip;
  if (carry && !resident) {
    prev_plane_offsets_.swap(plane_offsets_);
    prev_plane_collider_.swap(plane_collider_);
    if (friction) prev_collider_normal_.swap(collider_normal_);
    if (friction) old_slip.swap(plane_slip_);
  }
  DevicePlanes device;
  device.p_there = (first && p_on_device_) || resident;
  device.radius_there = first && searched_there_ && rows_true_radius_;
  device.entries_stay = c.s.contact_solver == kContactGaussSeidel
                            ? !c.impacts_here && !c.shapes_here &&
                                  (!c.s.use_opencl || open_device().builds_contacts())
                            : jacobi_planes_stay(c);
  device.entries_stay = device.entries_stay || resident;
  device.rows_stay = device.entries_stay && !c.s.fetch_plane_rows;
  if (resident && carry) open_device().hold_planes();
  // the device's planes take the predicted positions there; the host's (a mesh collider whose
  // queries it makes: meshes_here) read them here
  const bool device_planes = c.s.use_opencl && !meshes_here(c.s, c.colliders, c.collider_count);
  const float* p = device_planes ? p_for_device(c, device.p_there) : host_p(c);
  find_planes(P0_, p, c.origin, c.colliders, c.collider_count, c.s.neighbor_query_scale, c.threads,
              device_planes ? &device : nullptr);
  // the device's planes took the predicted positions (the solve copies them there); the impact
  // data its end would make read them there (else they are made here)
  if (first && planes_on_device_) p_on_device_ = true;
  if (!planes_on_device_) c.impacts_here = c.impacts;
  planes_kept_there_ =
      planes_on_device_ && device.entries_stay && c.s.contact_solver != kContactGaussSeidel;
  g.plane_offsets = plane_offsets_.data();
  g.plane = plane_.data();
  if (friction) {
    if (resident)
      resize_for_rewrite(collider_normal_, plane_offsets_[n]);
    else
      collider_normal_.assign(plane_offsets_[n], 0.0f);
    c.acc.collider = collider_normal_.data();
  }
  if (!carry) return;
  if (friction) {
    if (resident)
      resize_for_rewrite(plane_slip_, 3 * size_t(plane_offsets_[n]));
    else
      plane_slip_.assign(3 * size_t(plane_offsets_[n]), 0.0f);
    g.plane_slip = plane_slip_.data();
  }
  if (resident) {
    // (Iterations::carry_planes: the host's arrays sized for the new rows, their contents the
    // device's)
    open_device().carry_planes(n, friction, friction, c.impacts);
    if (friction) device_.plane_slips_stale = true;
    return;
  }
#pragma omp parallel for schedule(static) num_threads(c.threads)
  for (long i = 0; i < ln; ++i)
    gr_carry_plane_row(prev_plane_offsets_.data(), prev_plane_collider_.data(),
                       friction ? prev_collider_normal_.data() : nullptr,
                       friction ? old_slip.data() : nullptr, plane_offsets_.data(),
                       plane_collider_.data(), friction ? collider_normal_.data() : nullptr,
                       friction ? plane_slip_.data() : nullptr,
                       c.impacts ? collider_dx_.data() : nullptr, static_cast<int>(i));
}

// pins: their own group, after the averaged update and the shapes (kernels/pin.h)
void GrainsSolver::project_pins(SubstepContext& c) {
  float* p = p_.data();
  const long ln = static_cast<long>(n_);
  const gr_grains& g = c.g;
  const gr_params& prm = c.prm;
#pragma omp parallel for schedule(static) num_threads(c.threads)
  for (long i = 0; i < ln; ++i) gr_store3(p, i, gr_project_pin(&g, &prm, p, static_cast<int>(i)));
}

// use_opencl (opencl/iterations.h): one device call of `count` iterations on x (in place), then
// the friction pass once when `friction_after`; pins only in the whole-substep call (`whole`:
// the iterations' loop runs its own otherwise)
void GrainsSolver::device_passes(SubstepContext& c, float* x, int count, bool friction_after,
                                 bool whole, const opencl::JacobiSolve* w) {
  gr_grains gd = c.g;
  if (!whole) gd.targetP = nullptr;
  const bool friction_pass = c.pair_friction_pass || c.collider_friction_pass;
  // the pair sums stay there unless the host's history reads them (a rebuild of the rows
  // during the iterations, or a save the device cannot make, brings them: sync_sums)
  opencl::IterationSizes size = device_sizes(c);
  size.sums_stay = !c.s.host_history;
  // the collider sums stay there with the planes (sync_plane_slips brings them)
  size.collider_sums_stay = whole && planes_kept_there_;
  open_device().run(gd, c.prm, size, x, c.acc, count, whole ? friction_pass : friction_after,
                    whole ? c.s.accurate_friction : false, w ? *w : opencl::JacobiSolve());
  if (size.collider_sums_stay && c.acc.collider) device_.plane_slips_stale = true;
  if (gd.pair_slip) device_.slips_there = true;  // sent with it, or there already
  if (c.acc.pair && gd.nbr_offsets) device_.sums_there = true, device_.sums_stale = size.sums_stay;
  if (c.acc.friction_dx) device_.friction_there = true;
}

bool GrainsSolver::jacobi_whole(const SubstepContext& c) const {
  const bool again = (c.s.update_neighbors_during_iterations && c.pairs_on) ||
                     (c.s.update_collisions_during_iterations && c.colliders_on);
  return jacobi_loop_there(c.s, true) && !c.shapes_here && (!again || c.rebuilds_there);
}

// use_opencl with jacobi: the rows and planes found again during the iterations
// (update_*_during_iterations) on the device within its one call (JacobiSolve::rebuild), where
// the substep's first search of rows ran there and left them there (no constrained pairs
// dropped here, no test switch bringing them), its planes are found there (no mesh queried
// here), no rigid shapes are projected here and none of the test switches that keep a stage
// here is set
bool GrainsSolver::rebuilds_there(const SubstepContext& c) {
  const GrainsSettings& s = c.s;
  const bool rows = s.update_neighbors_during_iterations && c.pairs_on;
  const bool planes = s.update_collisions_during_iterations && c.colliders_on;
  if (!s.use_opencl || s.contact_solver == kContactGaussSeidel || !(rows || planes) ||
      c.shapes_here || (chebyshev_steps(s) && s.host_chebyshev) || s.host_history ||
      s.fetch_plane_rows || s.host_rebuilds)
    return false;
  if (rows && !(rows_on_device_ && device_.rows_stale)) return false;
  return !(planes && meshes_here(s, c.colliders, c.collider_count));
}

// jacobi_whole but for the shapes, which the device then projects too where it can, and for
// the rebuilds during the iterations where `rebuilds` (else none)
bool GrainsSolver::jacobi_loop_there(const GrainsSettings& s, bool rebuilds) {
  return s.use_opencl && s.contact_solver != kContactGaussSeidel &&
         !(chebyshev_steps(s) && s.host_chebyshev) && (rebuilds || !finds_again(s));
}

// Whether the rows and planes found again during the iterations (update_*_during_iterations)
// will be found there (rebuilds_there), as the substep knows it before its search: what the
// settings and the device say (rebuilds_chain), its rows may stay there (rows_stay: no
// constrained pairs dropped here) and its planes are found there (no mesh queried here).
// (Where the device then declines the first search, its buffers too small, find_pairs refuses
// the substep.)
bool GrainsSolver::rebuilds_fit(const SubstepContext& c) {
  const GrainsSettings& s = c.s;
  return rebuilds_chain(s) &&
         !(s.update_neighbors_during_iterations && c.pairs_on && !rows_stay(c)) &&
         !(s.update_collisions_during_iterations && c.colliders_on &&
           meshes_here(s, c.colliders, c.collider_count));
}

// rebuilds_fit as the settings and the device say it, whatever the grains: no test switch keeps
// the rebuilds or what they read here, and the device finds rows (double precision) and builds
// them (builds_contacts). For grains without primitives (no constraints), which the node's
// sleeping test on the device and a start held there need (grains_node.cpp), it is all of it
// but a mesh queried here, which those exclude themselves.
bool GrainsSolver::rebuilds_chain(const GrainsSettings& s) {
  if (!s.use_opencl || s.host_rebuilds || s.fetch_plane_rows || s.fetch_rows || s.host_history)
    return false;
  return !s.update_neighbors_during_iterations ||
         (open_device().builds_contacts() && open_device().shapes_there());
}

bool GrainsSolver::jacobi_planes_stay(const SubstepContext& c) const {
  return jacobi_whole(c) && !c.impacts_here && !c.s.host_history;
}

// use_opencl with jacobi: the substep's prediction, pre-stabilization, iterations and end chained
// on the device, the positions staying there between them (its end comes back, or stays, as
// gauss_seidel's does; carry_start takes the next start from it), where nothing between them
// runs here: no rigid shapes projected here, no rows or planes found again during the iterations
// but there (jacobi_whole; Chebyshev's step is made there too), no impact data against a mesh
// collider whose queries the host makes (meshes_here: its final collision test, and so the momenta,
// are the host's), no contact history made here (host_history), and none of the test switches
// send_history_p, host_predict and host_finish. Rows and planes found again during the
// iterations are found there too where they can be (rebuilds_fit).
bool GrainsSolver::jacobi_on_device(const SubstepContext& c) {
  return c.s.use_opencl && !c.shapes_here && jacobi_chain(c.s, rebuilds_fit(c)) &&
         !(c.d.impact_impulse && meshes_here(c.s, c.colliders, c.collider_count));
}

// The substep's end made on the device after its iterations (write_back takes what it wrote):
// `end` set up for it (opencl::SubstepEnd). The final collision test there too, on
// the colliders the device's planes took (with their meshes: a mesh whose queries the host makes
// keeps the planes here); the end stays there where the caller lets it (GrainsData::may_hold_end)
// and nothing here reads it: no final collision test here, no constraints' strain.
opencl::SubstepEnd* GrainsSolver::finish_there(const SubstepContext& c, opencl::SubstepEnd* end) {
  const size_t n = n_;
  finished_there_ = true;
  device_.end_P_stale = device_.end_v_stale = false;  // this end replaces the last one
  end_P_.resize(3 * n);
  end_v_.resize(3 * n);
  end->P_out = end_P_.data();
  end->v_out = end_v_.data();
  end->keep_velocity = c.s.keep_velocity;  // the start's, as the device holds them
  end->force = c.device_force;
  end->force_uniform = c.force_uniform;
  end->origin[0] = c.origin.x, end->origin[1] = c.origin.y, end->origin[2] = c.origin.z;
  collided_there_ = c.s.final_collision_test && planes_on_device_;
  if (collided_there_) {
    end->colliders = plane_colliders_.data();
    end->collider_count = plane_colliders_.size();
  }
  const bool test_here = c.s.final_collision_test && c.colliders_on && !collided_there_;
  end->stay = end_stays_ = c.d.may_hold_end && !test_here && !c.constraints_on;
  // the impact data made there too, unless they are made here
  if (c.impacts && !c.impacts_here) {
    end->impact_collider = c.d.impact_collider;
    end->impact_impulse = c.d.impact_impulse;
    end->impact_normal = c.d.impact_normal;
    end->impact_point = c.d.impact_point;
  }
  return end;
}

// the predicted positions for a device's call that takes them where the device holds them (its
// prediction, or a search's copy of it) when `there`: p_ unmade then, which it does not read;
// else the host's
float* GrainsSolver::p_for_device(const SubstepContext& c, bool there) {
  return there && device_.device && device_.device->holds_prediction(n_) ? p_.data() : host_p(c);
}

// the device, opened at the first substep that asks for it
opencl::Iterations& GrainsSolver::open_device() {
  if (!device_.device) device_.device = std::make_unique<opencl::Iterations>();
  return *device_.device;
}

// how much of each of the substep's arrays the device reads
opencl::IterationSizes GrainsSolver::device_sizes(const SubstepContext& c) const {
  opencl::IterationSizes size;
  size.n = n_;
  size.pair_entries = c.g.nbr_offsets ? neighbors_.offsets.back() : 0;
  size.plane_entries = c.g.plane_offsets ? plane_offsets_[n_] : 0;
  size.planes_there = planes_on_device_;
  size.rows_there = rows_on_device_;
  size.slips_there = device_.slips_there;
  size.sums_there = device_.sums_there;
  size.friction_there = device_.friction_there;
  size.plane_slips_there = device_.plane_slips_stale;
  size.prims = c.g.con_offsets ? c.d.prim_count : 0;
  size.row_length = row_length_;
  return size;
}

// the friction pass (gr_friction_pass) on every grain, p_ to p_ (through p_next_)
void GrainsSolver::run_friction(SubstepContext& c) {
  const float* p = p_.data();
  float* next = p_next_.data();
  const long ln = static_cast<long>(n_);
  if (c.s.use_opencl) {
    std::copy(p_.begin(), p_.end(), p_next_.begin());
    device_passes(c, next, 0, true, false);
  } else {
    const gr_grains& g = c.g;
    const gr_params& prm = c.prm;
    const gr_normal_sums& acc = c.acc;
#pragma omp parallel for schedule(static) num_threads(c.threads)
    for (long i = 0; i < ln; ++i) {
      int ii = static_cast<int>(i);
      gr_store3(next, ii, gr_friction_pass(&g, &prm, p, &acc, ii));
    }
  }
  p_.swap(p_next_);
  if (c.shapes_on) project_shapes(c.g, c.prm, c.threads);  // friction moved grains one by one
}

// The Jacobi iterations (gr_iterate), with rebuilds of the rows and planes during them, the
// shapes, the friction pass (after every iteration with accurate friction, else once after the
// loop) and the pins; friction is its own pass, never inside the contact gather. With use_opencl
// the device runs the grain loops: with nothing between them on the host (no shape matching, no
// rebuild during the iterations) every pass of the substep is one call, Chebyshev's step made
// there too; otherwise each pass is a call of its own and the host does the rest between them,
// as here.
void GrainsSolver::iterate(SubstepContext& c) {
  const GrainsSettings& s = c.s;
  const long ln = static_cast<long>(n_);
  const int threads = c.threads, iterations = c.iterations;
  const gr_grains& g = c.g;
  const gr_params& prm = c.prm;
  const bool friction_pass = c.pair_friction_pass || c.collider_friction_pass;
  const bool device = s.use_opencl;
  if (device) open_device();
  const bool chebyshev = chebyshev_steps(s);
  float omega = 1.0f;
  const bool device_whole = jacobi_whole(c);
  // x_{-1} = x_0: the first step is plain Jacobi (omega 1); the device's whole call keeps its own
  if (chebyshev && !device_whole) p_before_ = p_;
  // the Jacobi chain there (jacobi_on_device): the prediction the device holds, moved there by
  // pre-stabilization where it ran, and the substep's end there
  opencl::JacobiSolve w;
  opencl::SubstepEnd end;
  if (device_whole && c.jacobi_there) {
    w.p_there = p_on_device_ && (stable_there_ || !stabilized_);
    if (w.p_there) w.finish = finish_there(c, &end);
  }
  // (the impact data at that end, from the iterations' sums there; else here, from them)
  if (!w.finish) c.impacts_here = c.impacts;
  if (chebyshev) w.chebyshev_rho = s.chebyshev_rho;
  opencl::ShapeArrays shapes;
  if (device_whole && c.shapes_on) w.shapes = shape_arrays_there(c, &shapes);
  if (c.jacobi_there && !device_whole)
    throw std::logic_error("grains: the Jacobi substep chained on the device without its passes");
  // the rows and planes found again there before each iteration but the first, run()'s
  // arrays and sums rewritten for them
  if (device_whole && c.rebuilds_there)
    w.rebuild = [this, &c](gr_grains* g, opencl::IterationSizes* size, gr_normal_sums* acc) {
      const bool sums_stay = size->sums_stay, collider_sums_stay = size->collider_sums_stay;
      if (c.pairs_on && c.s.update_neighbors_during_iterations) find_pairs(c, false);
      if (c.colliders_on && c.s.update_collisions_during_iterations) update_planes(c, false);
      *g = c.g;  // (with the pins: the whole call's)
      *size = device_sizes(c);
      size->sums_stay = sums_stay, size->collider_sums_stay = collider_sums_stay;
      *acc = c.acc;
    };
  if (device_whole)
    device_passes(c, w.p_there ? p_.data() : host_p(c), iterations, false, true, &w);
  device_.p_there = device_whole;  // nothing here changes p_ before the history's save
  for (int it = 0; it < iterations && !device_whole; ++it) {
    if (it > 0 && c.pairs_on && s.update_neighbors_during_iterations) find_pairs(c, false);
    if (it > 0 && c.colliders_on && s.update_collisions_during_iterations) update_planes(c, false);
    const float* p = p_.data();
    // Chebyshev: the result overwrites the iterate before p_, which only grain i reads, for i
    float* next = chebyshev ? p_before_.data() : p_next_.data();
    omega = chebyshev ? gr_chebyshev_omega(it, s.chebyshev_rho, omega) : 1.0f;
    const float om = omega;
    if (device) {
      // the iteration on the device into p_next_, the Chebyshev step here
      std::copy(p_.begin(), p_.end(), p_next_.begin());
      device_passes(c, p_next_.data(), 1, false, false);
      const float* x_hat = p_next_.data();
      if (om != 1.0f) {
#pragma omp parallel for schedule(static) num_threads(threads)
        for (long i = 0; i < ln; ++i) {
          const int ii = static_cast<int>(i);
          gr_store3(next, ii, gr_chebyshev(gr_load3(x_hat, ii), gr_load3(next, ii), om));
        }
      } else if (next != x_hat) {
        std::copy(p_next_.begin(), p_next_.end(), p_before_.begin());
      }
    } else {
      const gr_normal_sums& acc = c.acc;
      const size_t stride = row_stride_;
#pragma omp parallel num_threads(threads)
      {
        gr_normal_sums mine = acc;  // this thread's row scratch
        if (mine.pair_iteration) mine.pair_iteration += stride * size_t(omp_get_thread_num());
        // static: a thread takes the same grains every iteration, so the positions it reads were
        // mostly written by itself and stay in its core's cache (with chunks handed out as they
        // come, half the reads fetched lines the other core had just written)
#pragma omp for schedule(static)
        for (long i = 0; i < ln; ++i) {
          int ii = static_cast<int>(i);
          gr_float3 x = gr_iterate(&g, &prm, p, ii, &mine);
          if (om != 1.0f) x = gr_chebyshev(x, gr_load3(next, ii), om);
          gr_store3(next, ii, x);
        }
      }
    }
    (chebyshev ? p_before_ : p_next_).swap(p_);
    if (c.shapes_on) project_shapes(g, prm, threads);
    if (friction_pass && s.accurate_friction) run_friction(c);
    if (g.targetP) project_pins(c);  // once an iteration, last
  }
  if (friction_pass && !s.accurate_friction && !device_whole) run_friction(c);
}

// Rigid shape matching's components: the connected components of the 2-point primitives
// (union-find) and their rest offsets, rebuilt from the start positions d.P whenever the grains
// or the primitives change (first seen, births, deaths, broken constraints); the same grains in
// another order keep their rest offsets by id; otherwise the stored rest offsets are kept.
void GrainsSolver::build_shapes(const GrainsData& d) {
  const size_t n = d.n;
  std::vector<int32_t> key;
  key.reserve(1 + n + 2 * d.prim_count);
  key.push_back(static_cast<int32_t>(n));
  for (size_t i = 0; i < n; ++i) key.push_back(grain_id(d, i));
  for (size_t e = 0; e < 2 * d.prim_count; ++e) {
    int32_t a = d.prim_points[e];
    key.push_back(a >= 0 && static_cast<size_t>(a) < n ? key[1 + a] : -1);
  }
  if (key != shape_key_) {
    // the same grains (unique ids) and primitives in another order (the node sorts its grains
    // by cell each frame): each grain keeps its rest offset, found by its id, rather than
    // having its rest shape taken again from where the grains are now
    std::vector<std::pair<int32_t, uint32_t>> was;  // (id, index in the last order), by id
    if (d.id && shape_key_.size() == key.size() && shape_key_[0] == key[0] &&
        std::equal(key.begin() + 1 + n, key.end(), shape_key_.begin() + 1 + n)) {
      std::vector<int32_t> ids(key.begin() + 1, key.begin() + 1 + n);
      for (size_t i = 0; i < n; ++i) was.push_back({shape_key_[1 + i], static_cast<uint32_t>(i)});
      std::sort(was.begin(), was.end());
      std::sort(ids.begin(), ids.end());
      bool same = std::adjacent_find(ids.begin(), ids.end()) == ids.end();
      for (size_t i = 0; same && i < n; ++i) same = was[i].first == ids[i];
      if (!same) was.clear();
    }
    std::vector<float> was_rest;
    if (!was.empty()) was_rest.swap(rest_offset_);  // made again below
    shape_key_.swap(key);
    ++shape_generation_;
    std::vector<int32_t> parent(n);
    for (size_t i = 0; i < n; ++i) parent[i] = static_cast<int32_t>(i);
    for (size_t e = 0; e < d.prim_count; ++e) {
      int32_t a = d.prim_points[2 * e], b = d.prim_points[2 * e + 1];
      if (a < 0 || b < 0 || static_cast<size_t>(a) >= n || static_cast<size_t>(b) >= n) continue;
      a = find_root(parent, a);
      b = find_root(parent, b);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
    // components in order of their smallest grain; singletons are left out
    std::vector<uint32_t> size(n, 0);
    for (size_t i = 0; i < n; ++i) size[find_root(parent, static_cast<int32_t>(i))]++;
    std::vector<int32_t> slot(n, -1);
    comp_offsets_.assign(1, 0);
    for (size_t i = 0; i < n; ++i)
      if (parent[i] == static_cast<int32_t>(i) && size[i] > 1) {
        slot[i] = static_cast<int32_t>(comp_offsets_.size()) - 1;
        comp_offsets_.push_back(comp_offsets_.back() + size[i]);
      }
    comp_members_.resize(comp_offsets_.back());
    std::vector<uint32_t> fill(comp_offsets_.begin(), comp_offsets_.end() - 1);
    for (size_t i = 0; i < n; ++i) {
      int32_t c = slot[find_root(parent, static_cast<int32_t>(i))];
      if (c >= 0) comp_members_[fill[c]++] = static_cast<uint32_t>(i);
    }
    // rest offsets from the mass-weighted centre of each component
    rest_offset_.assign(3 * n, 0.0f);
    if (!was.empty()) {
      for (size_t i = 0; i < n; ++i) {
        const int32_t id = shape_key_[1 + i];
        const auto at = std::lower_bound(was.begin(), was.end(), std::make_pair(id, uint32_t(0)));
        store3(rest_offset_.data(), i, load3(was_rest.data(), at->second));
      }
      return;
    }
    for (size_t c = 0; c + 1 < comp_offsets_.size(); ++c) {
      Vec3 centre;
      double msum = 0;
      for (uint32_t k = comp_offsets_[c]; k < comp_offsets_[c + 1]; ++k) {
        uint32_t i = comp_members_[k];
        centre += load3(d.P, i) * mass_[i];
        msum += mass_[i];
      }
      centre = centre / static_cast<float>(msum);
      for (uint32_t k = comp_offsets_[c]; k < comp_offsets_[c + 1]; ++k)
        store3(rest_offset_.data(), comp_members_[k], load3(d.P, comp_members_[k]) - centre);
    }
  }
}

// Pre-stabilization (gr_stabilize, Macklin et al. 2014 sec. 4.4): Jacobi passes of the contacts
// alone on the start positions P0_ into P_stable_, until no grain moves more than
// kStabilizeTolerance of its radius (at most `iterations` and kStabilizeIterations passes); the
// predicted positions p_ move by the same amounts, so the overlaps the substep began with are
// removed without becoming velocity. `pairs`: grain pairs take part (else collider planes only).
void GrainsSolver::pre_stabilize(const gr_grains& g, const gr_params& prm, bool pairs,
                                 int iterations, int threads, const SubstepContext* device) {
  const size_t n = n_;
  const long ln = static_cast<long>(n);
  gr_params ps = prm;
  ps.clumping_weight = 0.0f;
  gr_grains gs = g;
  if (!pairs) gs.nbr_offsets = nullptr;
  // no friction here: the contacts' carried slips are not read (nor sent to the device, 12
  // bytes an entry of the rows and planes)
  gs.pair_slip = gs.plane_slip = nullptr;
  P_stable_.resize(3 * n + 1);
  p_stable_next_.resize(3 * n + 1);
  // until no grain moves more than kStabilizeTolerance of its radius, at most
  // constraint_iterations passes (and kStabilizeIterations): at rest one pass finds almost
  // nothing and stops. The iterations' budget bounds it: a crushed pile at 20 x 2 ran 64
  // passes in most substeps, most of the substep's work, all of it without friction.
  const int stabilize_max = std::min(kStabilizeIterations, iterations);
  auto go_on = [&](int, float moved) {
    ++stabilize_passes_;
    return moved > kStabilizeTolerance;
  };
  // the same passes on the device (opencl/iterations.h); with the Jacobi chain there
  // (jacobi_on_device) the start and the prediction it moves stay there
  opencl::IterationSizes size;
  if (device) {
    size = device_sizes(*device);
    if (!pairs) size.pair_entries = 0;
    stable_there_ =
        device->jacobi_there && p_on_device_ &&
        open_device().stabilize(gs, ps, size, P_stable_.data(), stabilize_max, go_on, true);
    if (stable_there_) return;
    host_p(*device);  // the prediction here (and the start, where it was held there)
  }
  std::copy(P0_, P0_ + 3 * n, P_stable_.begin());
  if (device) open_device().stabilize(gs, ps, size, P_stable_.data(), stabilize_max, go_on);
  for (int k = 0; k < stabilize_max && !device; ++k) {
    const float* x = P_stable_.data();
    float* next = p_stable_next_.data();
    float moved = 0;
#pragma omp parallel for schedule(static) num_threads(threads) reduction(max : moved)
    for (long i = 0; i < ln; ++i) {
      const gr_float3 y = gr_stabilize(&gs, &ps, x, static_cast<int>(i));
      const gr_float3 d = gr_sub(y, gr_load3(x, static_cast<int>(i)));
      moved = std::max(moved, gr_length(d) / radius_[i]);
      gr_store3(next, i, y);
    }
    P_stable_.swap(p_stable_next_);
    ++stabilize_passes_;
    if (!(moved > kStabilizeTolerance)) break;
  }
  float* p = p_.data();
  const float* x = P_stable_.data();
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long i = 0; i < ln; ++i)
    for (int a = 0; a < 3; ++a) p[3 * i + a] += x[3 * i + a] - P0_[3 * i + a];
}

// The substep's end: velocity from the iterate (gr_update_velocity: blend, caps, drift), the
// swept final collision test against the colliders, P and v written back in world space (the
// substep's coordinates plus origin), and with `impacts` each collider's momentum on the grain
// (else the device's end made them, or none are asked for).
void GrainsSolver::write_back(GrainsData& d, const GrainsSettings& s, const gr_grains& g,
                              const gr_params& prm, const ColliderState* colliders,
                              size_t collider_count, const Vec3& origin, bool impacts,
                              int threads) {
  if (impacts) sync_planes();
  // the ids of the grains the device's end wrote, in its order (carry_start finds them there)
  if (finished_there_) {
    if (d.id)
      end_ids_.assign(d.id, d.id + d.n);
    else
      end_ids_.clear();
  }
  // the sleeping test's end on the device (sleep_begin), along the rows where they are, before
  // the box of what the end wrote is measured
  if (sleep_there_) {
    const bool device_rows = candidates_on_ && device_.rows_stale;
    // the colliders that moved this substep wake the sleepers they reach: the device's planes
    // took every collider, with its mesh (Iterations::set_meshes)
    if (!finished_there_ || (collider_count > 0 && !planes_on_device_) ||
        !device_.device->sleep_end(sleep_params_, d.n, device_rows,
                                   candidates_on_ && !device_rows ? &neighbors_ : nullptr,
                                   plane_colliders_.data(), collider_count))
      throw std::logic_error("grains: the device cannot end the sleeping test it began");
    sleep_back_time_.clear(), sleep_back_anchor_.clear(), sleep_back_accel_.clear();
    sleep_back_contacts_.clear();
    device_.end_P_stale = device_.end_v_stale = true;
  }
  // the device's end stays there when every position and velocity it wrote is finite (else
  // they come back, for the engine's check to name the grain), measured there with the box
  // that gives the next substep's origin
  if (finished_there_ && end_stays_) {
    float lo[3], hi[3];
    bool finite = false;
    if (device_.device->end_bounds(d.n, lo, hi, &finite) && finite) {
      device_.end_there = device_.end_P_stale = device_.end_v_stale = true;
      end_origin_ = box_origin(lo, hi);
      ++held_ends_;
      finish_P_ = d.P;
      end_changed_.clear();
      end_hit_.clear();
      return;
    }
    device_.end_P_stale = device_.end_v_stale = true;
  }
  if (finished_there_) sync_end(true, true);  // what the sleeping test changed there, too
  const long ln = static_cast<long>(d.n);
  const bool colliders_on = collider_count > 0;
  const float* p = p_.data();
  // the device's end of the substep (finished_there_), whose positions it keeps: the grains
  // the final collision test moves here are listed for contact_stats; the device's own test
  // (collided_there_) moved them there
  const bool there = finished_there_;
  const bool test_here = s.final_collision_test && colliders_on && !collided_there_;
  // the colliders in the shared functions' form, and their meshes (kernels/final_collision.h)
  std::vector<gr_collider> shapes(test_here ? collider_count : 0);
  std::vector<const void*> meshes(shapes.size());
  for (size_t c = 0; c < shapes.size(); ++c)
    shapes[c] = to_gr(colliders[c]), meshes[c] = colliders[c].shape.mesh.get();
  end_hit_.assign(there && test_here ? d.n : 0, 0);
  // the impact data's plane rows, where sync_planes left them
  gr_grains planes = g;
  planes.plane_offsets = plane_offsets_.data();
  planes.plane = plane_.data();
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long i = 0; i < ln; ++i) {
    int ii = static_cast<int>(i);
    const Vec3 a = load3(d.P, i);
    Vec3 b, v;
    if (there) {
      b = load3(end_P_.data(), i);
      v = load3(end_v_.data(), i);  // a kept start velocity too (as the device held it)
    } else {
      gr_float3 Pk, vk;
      gr_update_velocity(&g, &prm, p, ii, &Pk, &vk);
      if (s.keep_velocity) vk = gr_load3(d.v, ii);
      // back to world space (exact for a grain that stays: see local_origin)
      b = to_vec(Pk) + origin, v = to_vec(vk);
    }
    const Vec3 v_loop = v;
    int32_t hit = -1;
    Vec3 hit_n{};
    if (test_here && inv_mass_[i] > 0.0f) {  // a fixed grain stays where it is
      const float mu = s.friction_with_colliders * (d.friction ? d.friction[i] : 1.0f);
      hit = final_collision(shapes.data(), meshes.data(), collider_count, a, b, v, radius_[i], mu,
                            prm, &hit_n);
      if (there && hit >= 0) end_hit_[i] = 1;
    }
    store3(d.P, i, b);
    store3(d.v, i, v);
    // Momentum from each collider plane: its applied corrections dx_c moved the grain, and
    // v = (p - P) / dt turns a displacement into a velocity change dx_c / dt; the final pass
    // changes v directly (added to its collider's slot, or a free one). Blend and caps, which
    // act on v after the loop, are not counted (kernels/impact.h).
    if (impacts)
      impact_slots(planes, s.dt, i, collider_dx_.data(), plane_collider_.data(), b, v, v_loop, hit,
                   hit_n, d);
  }
  finish_P_ = d.P;
  end_changed_.clear();
  for (size_t i = 0; i < end_hit_.size(); ++i)
    if (end_hit_[i]) end_changed_.push_back(static_cast<gr_uint>(i));
}

const float* GrainsSolver::device_force(const gr_grains& g, bool* uniform) {
  *uniform = false;
  if (!g.force) return nullptr;
  const size_t n = n_;
  auto row = [&](size_t i) { return g.force + 3 * size_t(g.force_index ? g.force_index[i] : i); };
  const float* first = row(0);
  bool same = true;
  for (size_t i = 1; same && i < n; ++i) same = std::memcmp(row(i), first, 3 * sizeof(float)) == 0;
  if (same) {
    *uniform = true;
    return first;
  }
  end_force_.resize(3 * n);
  for (size_t i = 0; i < n; ++i) std::copy_n(row(i), 3, &end_force_[3 * i]);
  return end_force_.data();
}

// Overlap statistics of the written positions over the neighbour rows, serial in a fixed order
// (the same for any thread count): touching pairs, the largest and mean overlap / summed radii
// (gr_row_overlaps). Rows left on the device are read there, in runs added in order.
void GrainsSolver::contact_stats(const GrainsData& d, GrainsStats* stats) const {
  const size_t n = d.n;
  double contacts = 0, sum = 0;
  float largest = 0;
  opencl::Iterations::RowOverlaps there;
  // the positions the device's end of the substep wrote there, but those write_back changed
  const std::vector<gr_uint>* written =
      finished_there_ && d.P == finish_P_ ? &end_changed_ : nullptr;
  if (read_rows(!written) && device_.device->row_overlaps(
                                 d.P, rows_true_radius_ ? nullptr : radius_, n, &there, written)) {
    contacts = there.contacts, largest = there.largest, sum = there.sum;
    written_on_device_ = d.P;
    ++overlaps_device_;
  } else {
    sync_rows();
    if (device_.end_there) {  // the end held there, here
      sync_end(true, false);
      std::copy_n(end_P_.data(), 3 * n, d.P);
    }
    gr_row_overlaps(d.P, radius_, neighbors_.offsets.data(), neighbors_.indices.data(), 0,
                    static_cast<int>(n), &contacts, &largest, &sum);
  }
  stats->contacts = static_cast<decltype(stats->contacts)>(contacts);
  stats->max_penetration = largest;
  if (contacts > 0) stats->mean_penetration = static_cast<float>(sum / contacts);
}

// The rows just built from the predicted positions p_ hold every candidate within
// query_scale x the summed (search) radii, nearest first, cut at max_neighbors. A pair that is
// not in a row was at least skin apart from touching: the reach beyond the summed radii, or,
// for a cut row, its farthest kept candidate's distance beyond them. Until some grain has moved
// half the skin no such pair can touch; the solver rebuilds at a quarter, leaving the other
// quarter to the iterations' own corrections within a substep.
void GrainsSolver::remember_rows(const GrainsData& d, const GrainsSettings& s,
                                 const float* search_radius, const float* p, int threads) {
  const size_t n = d.n;
  const long ln = static_cast<long>(n);
  rows_valid_ = s.neighbor_query_scale > 1;
  rows_query_scale_ = s.neighbor_query_scale;
  rows_max_ = s.max_neighbors;
  rows_uniform_ = s.assume_uniform_radius;
  if (!rows_valid_) return;
  rows_ids_.resize(n);
  for (size_t i = 0; i < n; ++i) rows_ids_[i] = grain_id(d, i);
  rows_radius_.assign(radius_, radius_ + n);
  // the positions the rows were built from: p, or the device's, where its search took them
  // from its prediction (null p), left there for its Verlet test
  device_.rows_p_stale = !p;
  if (p) rows_p_.assign(p, p + 3 * n);
  float r_min = std::numeric_limits<float>::infinity(), r_max = 0;
  for (size_t i = 0; i < n; ++i) {
    r_min = std::min(r_min, search_radius[i]);
    r_max = std::max(r_max, radius_[i]);
  }
  // the true radii may exceed the searched ones only where they are the searched ones
  float skin = (s.neighbor_query_scale - 1) * 2 * r_min;
  // the cut rows' reach (gr_row_reach; the smallest in any order), where the rows are
  const gr_uint full = s.max_neighbors > 0 ? static_cast<gr_uint>(s.max_neighbors) : 0u;
  float reach = std::numeric_limits<float>::infinity();
  if (!(device_.rows_stale &&
        device_.device->row_reach(rows_true_radius_ ? nullptr : radius_, n, full, r_max, &reach))) {
    sync_rows();
    sync_rows_p();
    p = rows_p_.data();
    const gr_uint* offsets = neighbors_.offsets.data();
    const gr_uint* indices = neighbors_.indices.data();
#pragma omp parallel for schedule(static) num_threads(threads) reduction(min : reach)
    for (long i = 0; i < ln; ++i)
      gr_row_reach(p, radius_, offsets, indices, int(i), int(i) + 1, full, r_max, &reach);
  }
  rows_skin_ = std::min(skin, reach);
}

// ---- checkpoint ----

void GrainsSolver::save_state(StateWriter& w) const {
  sync_device();  // the rows the device kept and the loads its list ended with
  w.section("grains rows");
  w.value(rows_valid_);
  w.value(rows_skin_);
  w.value(rows_query_scale_);
  w.value(rows_max_);
  w.value(rows_uniform_);
  w.array(rows_ids_);
  w.array(rows_radius_);
  w.array(rows_p_);
  w.array(neighbors_.offsets);
  w.array(neighbors_.indices);
  w.section("grains history");
  w.array(hist_id_);
  w.array(hist_rows_.offsets);
  w.array(hist_rows_.indices);
  w.array(hist_plane_offsets_);
  w.array(hist_plane_collider_);
  w.array(hist_slip_);
  w.array(hist_plane_slip_);
  w.section("grains shapes");
  w.array(shape_key_);
  w.array(comp_offsets_);
  w.array(comp_members_);
  w.array(rest_offset_);
  w.section("grains loads");
  w.value(seq_dt_);
  w.array(seq_loads_);
}

void GrainsSolver::load_state(StateReader& r) {
  sleep_state_n_ = 0;  // the node sends its attributes' state again
  sleep_there_ = slept_there_ = false;
  r.section("grains rows");
  r.value(rows_valid_);
  longest_known_ = false;  // not saved: measured again
  r.value(rows_skin_);
  r.value(rows_query_scale_);
  r.value(rows_max_);
  r.value(rows_uniform_);
  r.array(rows_ids_);
  r.array(rows_radius_);
  r.array(rows_p_);
  r.array(neighbors_.offsets);
  r.array(neighbors_.indices);
  rows_on_device_ = false;
  r.section("grains history");
  r.array(hist_id_);
  r.array(hist_rows_.offsets);
  r.array(hist_rows_.indices);
  r.array(hist_plane_offsets_);
  r.array(hist_plane_collider_);
  r.array(hist_slip_);
  r.array(hist_plane_slip_);
  r.section("grains shapes");
  r.array(shape_key_);
  ++shape_generation_;
  r.array(comp_offsets_);
  r.array(comp_members_);
  r.array(rest_offset_);
  r.section("grains loads");
  r.value(seq_dt_);
  r.array(seq_loads_);
  check_state(r);
  index_loads();
  seq_valid_ = false;
  device_.holds_contacts = device_.stale = device_.rows_stale = device_.rows_p_stale = false;
  device_.hist_stale = device_.slips_stale = device_.slips_there = false;
  device_.hist_planes_stale = device_.plane_slips_stale = false;
  device_.sums_there = device_.sums_stale = device_.friction_there = false;
}

namespace {

// rows as saved (offsets, then entries): none, or ascending offsets from 0 to at most the
// entries' count, each entry below `bound`
void check_rows(const StateReader& r, const std::vector<uint32_t>& offsets, size_t entries,
                const uint32_t* entry, size_t bound, const std::string& what) {
  if (offsets.empty()) return;
  if (offsets.front() != 0 || offsets.back() > entries ||
      !std::is_sorted(offsets.begin(), offsets.end()))
    r.fail(what + ": offsets that do not run from 0 within their entries");
  for (size_t e = 0; entry && e < offsets.back(); ++e)
    if (entry[e] >= bound)
      r.fail(what + ": entry " + std::to_string(entry[e]) + " of " + std::to_string(bound));
}

void check_finite(const StateReader& r, const float* a, size_t count, const std::string& what) {
  for (size_t k = 0; k < count; ++k)
    if (!std::isfinite(a[k])) r.fail(what + ": a value that is not finite");
}

}  // namespace

// A checkpoint's solver state, read as saved, checked as far as the next substep reads it: the
// rows, history and rest shapes index one another and the grains, and a file altered with its
// checksum made again must not send them out of range. (The history's own rows, hist_rows_, are
// the rows before a rebuild: a substep copies them from neighbors_ before it reads them.)
void GrainsSolver::check_state(const StateReader& r) const {
  const size_t m = rows_ids_.size();
  if (!std::isfinite(rows_skin_) || !std::isfinite(rows_query_scale_))
    r.fail("the grains' rows have a skin that is not finite");
  if (rows_valid_ && (rows_radius_.size() != m || rows_p_.size() != 3 * m ||
                      (!neighbors_.offsets.empty() && neighbors_.offsets.size() != m + 1)))
    r.fail("the grains' rows were built for another number of grains");
  check_finite(r, rows_radius_.data(), rows_radius_.size(), "the grains' rows' radii");
  check_finite(r, rows_p_.data(), rows_p_.size(), "the grains' rows' positions");
  const size_t rows = neighbors_.offsets.empty() ? 0 : neighbors_.offsets.size() - 1;
  if (!neighbors_.offsets.empty() && neighbors_.offsets.back() != neighbors_.indices.size())
    r.fail("the grains' neighbour rows: offsets that do not end at their entries");
  check_rows(r, neighbors_.offsets, neighbors_.indices.size(), neighbors_.indices.data(), rows,
             "the grains' neighbour rows");
  // the pairs' carried slips: an entry of those rows each, for these grains
  const size_t k = hist_id_.size();
  if (!hist_slip_.empty() &&
      (rows != k || hist_slip_.size() != 3 * size_t(neighbors_.indices.size())))
    r.fail("the contact history's slips do not match the grains' rows");
  check_finite(r, hist_slip_.data(), hist_slip_.size(), "the contact history's slips");
  const size_t old_rows = hist_rows_.offsets.empty() ? 0 : hist_rows_.offsets.size() - 1;
  check_rows(r, hist_rows_.offsets, hist_rows_.indices.size(), hist_rows_.indices.data(),
             std::max(old_rows, k), "the contact history's rows");
  // the planes' carried slips: a row of planes for each grain of the history
  if (k > 0 && !hist_plane_offsets_.empty() && hist_plane_offsets_.size() != k + 1)
    r.fail("the contact history's planes do not match its grains");
  check_rows(r, hist_plane_offsets_, hist_plane_collider_.size(), nullptr, 0,
             "the contact history's planes");
  if (!hist_plane_offsets_.empty() &&
      hist_plane_slip_.size() < 3 * size_t(hist_plane_offsets_.back()))
    r.fail("the contact history's plane slips do not match its planes");
  check_finite(r, hist_plane_slip_.data(), hist_plane_slip_.size(),
               "the contact history's plane slips");
  if (!shape_key_.empty()) {
    const int32_t grains = shape_key_[0];
    if (grains < 0 || shape_key_.size() < 1 + size_t(grains) ||
        rest_offset_.size() != 3 * size_t(grains) || comp_offsets_.empty() ||
        comp_offsets_.back() != comp_members_.size())
      r.fail("the rigid shapes were built for another number of grains");
    check_rows(r, comp_offsets_, comp_members_.size(), comp_members_.data(), size_t(grains),
               "the rigid shapes' components");
    check_finite(r, rest_offset_.data(), rest_offset_.size(), "the rigid shapes' rest offsets");
  }
  if (!std::isfinite(seq_dt_) || seq_dt_ < 0) r.fail("the carried loads' substep is not a time");
  for (const SeqLoad& l : seq_loads_) {
    const float load[4] = {l.ln, l.lt[0], l.lt[1], l.lt[2]};
    check_finite(r, load, 4, "the carried loads");
  }
}

// ---- contact history ----
// The friction of a substep removes the slip of that substep; what the Jacobi iterations leave of
// it (a grain between neighbours that slip opposite ways is pulled both ways at once) would be
// forgotten, and a heap would flow slowly like a liquid however large its friction. Each contact
// that pushed in the substep and whose grain did not slide keeps its left-over tangential slip,
// and the next substep's friction removes it with its own: a contact creeps back to where it
// stuck, within the same Coulomb bound, as a DEM contact's tangential spring pulls it back.

int32_t GrainsSolver::previous_index(int32_t id) const {
  if (id < 0 || static_cast<size_t>(id) >= hist_lookup_.size()) return -1;
  return hist_lookup_[id];
}

bool GrainsSolver::history_ids(size_t n, int32_t* top) const {
  *top = -1;
  for (int32_t id : hist_id_) {
    if (id < 0) return false;
    *top = std::max(*top, id);
  }
  return !hist_id_.empty() && static_cast<size_t>(*top) <= 8 * n + 1024;
}

void GrainsSolver::load_history(const GrainsData& d, bool pairs, bool planes, bool same_rows,
                                int threads, const SubstepContext* device) {
  const size_t n = d.n;
  const long ln = static_cast<long>(n);
  const size_t entries = neighbors_.offsets.empty() ? 0 : neighbors_.offsets.back();
  // the rows are last substep's: each entry's slip is where it was saved
  const bool kept = pairs && same_rows && hist_slip_.size() == 3 * entries;
  // last substep's grains by id (ids far sparser than the grains: no history); `same`, they
  // are these grains in this order, each its own index there (the device then needs no ids)
  int32_t top = -1;
  const bool ids = history_ids(n, &top);
  bool same = ids && hist_id_.size() == n;
  for (size_t i = 0; i < n && same; ++i) same = hist_id_[i] == grain_id(d, i);
  const size_t table = ids && !same ? size_t(top) + 1 : 0;
  const int32_t* hist_ids = ids && !same ? hist_id_.data() : nullptr;
  // the slips the device saved: the carried ones made there too, where its search's rows are
  bool made_there = false;
  if (pairs && device_.hist_stale) {
    made_there = device && open_device().load_pair_history(device_sizes(*device), kept, same, d.id,
                                                           kept ? nullptr : hist_ids,
                                                           hist_id_.size(), kept ? 0 : table);
    if (made_there) {
      hist_lookups_device_ += !kept && ids;
      pair_slip_.resize(3 * entries);
      device_.slips_stale = device_.slips_there = true;
    } else {
      sync_pair_history();
    }
  }
  if (kept && !made_there)
    pair_slip_.swap(hist_slip_);
  else if (pairs && !made_there)
    pair_slip_.assign(3 * entries, 0.0f);
  // the planes' carried slips made there from the save kept there, where this substep's planes
  // stay there too (jacobi_planes_stay)
  bool planes_there = false;
  if (planes) {
    plane_slip_.assign(3 * size_t(plane_offsets_[n]), 0.0f);
    if (device_.hist_planes_stale && device && planes_kept_there_) {
      planes_there = open_device().load_plane_history(device_sizes(*device), same, d.id, hist_ids,
                                                      hist_id_.size(), table);
      hist_plane_loaded_device_ += planes_there;
      device_.plane_slips_stale = planes_there;
    }
    if (!planes_there) sync_plane_history();
  }
  const bool lookup_pairs = pairs && !kept && !made_there && !hist_slip_.empty();
  const bool lookup_planes = planes && !planes_there;
  if (hist_id_.empty() || (!lookup_pairs && !lookup_planes) || !ids) return;
  if (lookup_pairs) sync_rows();     // the host looks each entry up in its row
  if (lookup_planes) sync_planes();  // ... and each plane in its grain's planes
  hist_lookup_.assign(size_t(top) + 1, -1);
  for (size_t i = 0; i < hist_id_.size(); ++i) hist_lookup_[hist_id_[i]] = static_cast<int32_t>(i);
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long i = 0; i < ln; ++i) {
    const int32_t h = previous_index(grain_id(d, i));
    if (h < 0) continue;
    if (lookup_pairs)
      gr_load_pair_slips(neighbors_.offsets.data(), neighbors_.indices.data(), d.id,
                         static_cast<int>(i), h, hist_rows_.offsets.data(),
                         hist_rows_.indices.data(), hist_id_.data(), hist_slip_.data(),
                         pair_slip_.data());
    if (lookup_planes)  // the history here holds the planes that pushed alone
      gr_load_plane_slips(plane_offsets_.data(), plane_collider_.data(), static_cast<int>(i), h,
                          hist_plane_offsets_.data(), hist_plane_collider_.data(), nullptr,
                          hist_plane_slip_.data(), plane_slip_.data());
  }
}

void GrainsSolver::save_history(const GrainsData& d, const GrainsSettings& s, const gr_grains& g,
                                const gr_params& prm, const float* p, bool pairs, bool planes,
                                int threads, const SubstepContext* device) {
  const size_t n = d.n;
  const long ln = static_cast<long>(n);
  // the iterations' end where the device holds it (device_passes), which it then reads there
  const bool p_there = p == p_.data() && device_.p_there && !s.send_history_p;
  hist_id_.resize(n);
  for (size_t i = 0; i < n; ++i) hist_id_[i] = grain_id(d, i);
  // pairs: one slip per entry of the rows (0: the contact did not push in the substep), so that
  // rows kept for the next substep find theirs in place; the lookup after a rebuild reads the
  // rows from hist_rows_
  hist_slip_.resize(pairs ? 3 * size_t(neighbors_.offsets.back()) : 0);
  // on the device where its search's rows are: they stay there (hist_slip_ is then the
  // device's until sync_history)
  const bool pairs_there = pairs && device &&
                           open_device().save_pair_history(g, prm, device_sizes(*device), p,
                                                           pair_normal_.data(), p_there);
  device_.hist_stale = pairs_there;
  hist_saved_device_ += pairs_there;
  // the host reads them, and the rows, which the next substep's lookup reads (hist_rows_)
  gr_grains gh = g;
  if (pairs && !pairs_there) {
    sync_slips(), sync_sums(), sync_rows();
    gh.nbr_indices = neighbors_.indices.data();
  }
  // the planes' slips, an entry each: kept on the device with the planes they belong to where
  // those stay there (jacobi_planes_stay; hist_plane_*_ are then the device's until
  // sync_history) and it holds the iterations' end (or the pairs' save sent it), else into
  // plane_saved_, made on the device where the iterations' end is there, then those of the
  // planes that pushed
  bool planes_there = false, planes_kept = false;
  if (planes && device && (p_there || pairs_there) && planes_kept_there_)
    planes_kept = open_device().save_plane_history(g, prm, device_sizes(*device),
                                                   collider_normal_.data(), nullptr);
  device_.hist_planes_stale = planes_kept;
  hist_plane_saved_device_ += planes_kept;
  if (planes && !planes_kept) {
    sync_planes();
    sync_plane_slips();
    plane_saved_.resize(3 * size_t(plane_offsets_[n]));
    planes_there = device && p_there &&
                   open_device().save_plane_history(g, prm, device_sizes(*device),
                                                    collider_normal_.data(), plane_saved_.data());
    hist_plane_saved_device_ += planes_there;
    hist_plane_offsets_.assign(n + 1, 0);
#pragma omp parallel for schedule(static) num_threads(threads)
    for (long i = 0; i < ln; ++i) {
      uint32_t c = 0;
      for (uint32_t e = plane_offsets_[i]; e < plane_offsets_[i + 1]; ++e)
        c += collider_normal_[e] > 0.0f ? 1 : 0;
      hist_plane_offsets_[i + 1] = c;
    }
    for (size_t i = 0; i < n; ++i) hist_plane_offsets_[i + 1] += hist_plane_offsets_[i];
    hist_plane_collider_.resize(hist_plane_offsets_[n]);
    hist_plane_slip_.resize(3 * size_t(hist_plane_offsets_[n]));
  } else if (!planes) {
    hist_plane_offsets_.assign(n + 1, 0);
  }
  // where the host makes a part of the history that the device's end left there: the
  // iterations' end, and the start they read where it is the device's alone (pre-stabilized
  // there, or held there: d.P and P0_ may be the end here now), into P_stable_
  gr_grains gp = g;
  const bool planes_here = planes && !planes_kept && !planes_there;
  if (finished_there_ && p == p_.data() && ((pairs && !pairs_there) || planes_here)) {
    const bool start_there = stable_there_ || start_held_;
    if (start_there) P_stable_.resize(3 * n + 1);
    if (!device_.device->fetch_run(p_.data(), start_there ? P_stable_.data() : nullptr, n))
      throw std::logic_error("grains: the device no longer holds the iterations' end");
    if (start_there) gh.P = gp.P = P_stable_.data();
  }
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long i = 0; i < ln; ++i) {
    if (pairs && !pairs_there)
      save_pair_slips(gh, prm, p, pair_normal_.data(), i, hist_slip_.data());
    if (!planes || planes_kept) continue;
    if (!planes_there)
      save_plane_slips(gp, prm, p, collider_normal_.data(), i, plane_saved_.data());
    uint32_t m = hist_plane_offsets_[i];
    for (uint32_t e = plane_offsets_[i]; e < plane_offsets_[i + 1]; ++e) {
      if (!(collider_normal_[e] > 0.0f)) continue;
      hist_plane_collider_[m] = plane_collider_[e];
      std::copy_n(&plane_saved_[3 * size_t(e)], 3, &hist_plane_slip_[3 * size_t(m)]);
      ++m;
    }
  }
}

}  // namespace grains
