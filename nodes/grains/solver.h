// The grains PBD solver (DESIGN §4, the POP Grains help page): one substep over a compact set of
// grains. The grains node gathers the particles of its stream/group into GrainsData, calls
// GrainsSolver::substep, and scatters P, v (and shockmass) back.
//
// Design: Jacobi iterations with gather-style corrections. Every particle reads the previous
// iterate of its neighbours and writes only its own next iterate, so the result is the same for
// any thread count (no atomics), and the per-particle math lives in kernels/*.h, written in the
// common subset of C++ and OpenCL C, so an OpenCL path compiles the same source.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/collider.h"
#include "engine/neighbors.h"
#include "engine/state_stream.h"
#include "nodes/grains/kernels/params.h"  // gr_grains, gr_params: the kernels' inputs
#include "nodes/grains/kernels/sequential.h"  // gr_seq_contact
#include "nodes/grains/kernels/shapes.h"      // gr_shapes
#include "nodes/grains/kernels/sleep.h"       // gr_sleep_params

namespace grains {

namespace opencl {
class Iterations;
struct IterationSizes;
struct SequentialContacts;
struct SubstepEnd;
struct JacobiSolve;
struct ShapeArrays;
struct Traffic;
}

enum class MassShock { Off = 0, Global = 1, Local = 2 };
// mass_shock_method's choices, in its menu's order (kernels/param_table.h)
enum MassShockMethod { kShockGlobal = 0, kShockLocal = 1 };
enum ContactSolver { kContactJacobi = 0, kContactGaussSeidel = 1 };

// removes the parentheses of a table's vector default: GR_UNPAREN (0, 1, 0) is 0, 1, 0
#define GR_UNPAREN(...) __VA_ARGS__

// Parameters of one substep, already evaluated (expressions resolved) by the node: one member per
// row of kernels/param_table.h, named as the graph names it, with the row's default, and what the
// node adds from the moment being computed.
struct GrainsSettings {
#define GR_SETTING_FLOAT(name, def) float name = def;
#define GR_SETTING_INT(name, def) int name = def;
#define GR_SETTING_TOGGLE(name, def) bool name = def;
#define GR_SETTING_VECTOR(name, def) Vec3 name{GR_UNPAREN def};
#define GR_SETTING_MENU(name, def) int name = def;
#define GR_SETTING_STRING(name, def) std::string name = def;
#define GR_PARAM(kind, name, def, home, modifiers, meaning) GR_SETTING_##kind(name, def)
#include "nodes/grains/kernels/param_table.h"
#undef GR_PARAM
#undef GR_SETTING_FLOAT
#undef GR_SETTING_INT
#undef GR_SETTING_TOGGLE
#undef GR_SETTING_VECTOR
#undef GR_SETTING_MENU
#undef GR_SETTING_STRING

  float dt = 1.0f / 48;  // substep length (s)
  int substeps = 1;      // the solver's substeps per frame (stiffness scaling)
  // the substep those substeps give (s; 0: dt): clumping's pull, a fraction of the gap each
  // substep, is scaled by (dt / base_dt)^2 when error control takes finer ones (make_params)
  float base_dt = 0;
  // the first substep after error control refined the step: its constraints remove the overlap
  // the coarser step left, but the grains keep the velocity they started with, since that
  // overlap, resolved in one finer step, would become a speed overlap / dt (from
  // TimeInfo::stabilize)
  bool keep_velocity = false;
  int threads = 0;  // 0: OpenMP default
  // contact_solver gauss_seidel's sweep order within a block: in waves (GrainsSolver::
  // order_waves), the order a device whose work-items share a block needs, instead of by lower
  // index. The solver takes it by itself for such a device (use_opencl on a GPU); set, the CPU
  // path sweeps the device's order (the tests compare the two)
  bool sweep_waves = false;
  // use_opencl: the host ends the substep (velocity update) even where the device could
  // (SubstepEnd), bringing the solved positions back; with jacobi the whole chain on the
  // device is off (GrainsSolver::jacobi_on_device: the host predicts and pre-stabilizes too).
  // The tests compare the two.
  bool host_finish = false;
  // use_opencl: every substep's start positions and velocities go up whole, even where the
  // device makes them from the last substep's end (GrainsSolver::carry_start; the tests compare
  // the two)
  bool resend_start = false;
  // use_opencl (gauss_seidel, or jacobi's chain there): the host's predicted positions go up,
  // even where the device makes the same floats (GrainsSolver::predict; the tests compare the
  // two)
  bool host_predict = false;
  // use_opencl: the collider planes' rows and colliders come back every substep, even where the
  // device compares them with the contact list's (gauss_seidel) or the Jacobi path keeps them
  // there (jacobi_planes_stay; the tests compare the two)
  bool fetch_plane_rows = false;
  // use_opencl with jacobi: the contacts' slips are saved and carried on the host, even where the
  // device could where its search's rows are (GrainsSolver::save_history; the tests compare the
  // two)
  bool host_history = false;
  // use_opencl: the neighbour rows come back after each search of the device's, even where the
  // substep reads them only there (GrainsSolver::rows_stay; the tests compare the two)
  bool fetch_rows = false;
  // use_opencl with jacobi: the positions the contact history's save reads go up, even where
  // the device holds them from the iterations (GrainsSolver::save_history; the tests compare
  // the two)
  bool send_history_p = false;
  // use_opencl with jacobi: Chebyshev's step made on the host between the iterations, each a
  // device call of its own, even where the device's whole call of them makes it
  // (GrainsSolver::jacobi_whole; the tests compare the two)
  bool host_chebyshev = false;
  // use_opencl: rigid shapes projected on the host between the passes, each a device call of
  // its own, even where the device projects them (SubstepContext::shapes_here; the tests compare
  // the two)
  bool host_shapes = false;
  // use_opencl: a mesh collider's planes, final collision test, impact data and sleepers' wake
  // made on the host, even where the device makes them (GrainsSolver::meshes_here; the tests
  // compare the two)
  bool host_mesh = false;
  // use_opencl with jacobi: the rows and planes found again during the iterations
  // (update_*_during_iterations) between device calls of an iteration each, the host carrying
  // their sums over, even where the device's whole call of them finds them there
  // (GrainsSolver::rebuilds_there; the tests compare the two)
  bool host_rebuilds = false;

  MassShock mass_shock() const {
    if (!enable_mass_shock_scaling) return MassShock::Off;
    return mass_shock_method == kShockGlobal ? MassShock::Global : MassShock::Local;
  }
  void set_mass_shock(MassShock m) {
    enable_mass_shock_scaling = m != MassShock::Off;
    mass_shock_method = m == MassShock::Local ? kShockLocal : kShockGlobal;
  }
};

// The grains node's sleeping test made on the device around a substep (use_opencl; GrainsData::
// sleep, GrainsSolver::sleeps_on_device; kernels/sleep.h): its speeds and times, which grains
// may sleep (n, null: every grain with a mass; a pinned one may not) and the state to send (the
// node's attributes, n, n x 3, n x 3 and n), all null where the device's from the last substep
// stands (sleep_state_there). The node's d.mass is then each grain's mass awake.
struct GrainsSleep {
  gr_sleep_params params{};
  const uint8_t* can = nullptr;
  const float* time = nullptr;
  const float* anchor = nullptr;
  const float* accel = nullptr;
  const int32_t* contacts = nullptr;
};

// Compact per-grain arrays (n grains). Optional attribute arrays are nullptr when the point
// attribute is missing (= 1, the help page's default scale).
struct GrainsData {
  size_t n = 0;
  float* P = nullptr;       // (n x 3) m, in: start of substep, out: end
  float* v = nullptr;       // (n x 3) m/s, in/out
  const float* force = nullptr;  // (n x 3) N, or the caller's (points x 3) with force_index
  const uint32_t* force_index = nullptr;  // (n) optional: grain i's force is force[force_index[i]]
  const float* mass = nullptr;   // (n) kg
  const float* pscale = nullptr;  // (n) m, radius
  const float* friction = nullptr;             // (n) optional
  const float* repulsionweight = nullptr;      // (n) optional
  const float* repulsionstiffness = nullptr;   // (n) optional
  const float* attractionweight = nullptr;     // (n) optional
  const float* attractionstiffness = nullptr;  // (n) optional
  float* shockmass = nullptr;  // (n) out when mass_shock == Global (may be nullptr otherwise)
  // explicit constraints: m 2-point primitives over these grains. A primitive whose endpoints
  // are out of range or equal is ignored (neither solved nor removed).
  size_t prim_count = 0;                        // m
  const int32_t* prim_points = nullptr;         // (m x 2) grain indices in [0, n)
  const float* restlength = nullptr;            // (m) m
  const float* strength = nullptr;              // (m) optional (1)
  float* strain = nullptr;                      // (m) in/out (may be nullptr: not written)
  uint8_t* prim_dead = nullptr;                 // (m) out: 1 = broken or a strand; may be nullptr
  const float* constraintweight = nullptr;      // (n) optional
  const float* constraintstiffness = nullptr;   // (n) optional
  const int32_t* id = nullptr;  // (n) stable point ids (shape matching's rest shapes), optional
  // pins: on when targetstiffness is set (a missing attribute = no pin, help page)
  const float* targetP = nullptr;          // (n x 3) m; nullptr with targetstiffness: origin
  const float* targetweight = nullptr;     // (n) optional
  const float* targetstiffness = nullptr;  // (n) nullptr: no pins
  // use_opencl with gauss_seidel: the substep's end may stay on the device (may_hold_end; the
  // caller then reads P and v only through GrainsSolver::end_positions and end_velocities, or
  // starts the next substep from there), and the substep starts from such an end (start_held:
  // P and v are not read, only written)
  bool may_hold_end = false;
  bool start_held = false;
  // the sleeping test on the device around this substep (GrainsSleep), or null
  const GrainsSleep* sleep = nullptr;
  // rigid shape matching: its connectivity is the 2-point primitives above (prim_points), dead
  // ones included until they are removed
  // collider contacts, out (impact data, collision feedback); all set or all nullptr. Each grain
  // has kContactSlots slots (its collider planes; the final pass's hit adds to its collider's
  // slot or takes a free one): (n x kContactSlots) entries.
  float* impact_impulse = nullptr;  // (n x slots x 3) N s: momentum the grain got from the collider
  float* impact_point = nullptr;    // (n x slots x 3) m: contact point on the collider surface
  float* impact_normal = nullptr;   // (n x slots x 3) unit, out of the collider
  int32_t* impact_collider = nullptr;  // (n x slots) collider index, -1: empty slot
};

// Per-substep diagnostics.
struct GrainsStats {
  float max_penetration = 0;   // max overlap / (r_i + r_j) over pairs after the substep
  float mean_penetration = 0;  // mean over overlapping pairs
  size_t contacts = 0;         // overlapping pairs
  float max_strain = 0;        // max |strain| over the constraints after the substep
  size_t broken = 0;           // constraints removed this substep (broken or strands)
};

class GrainsSolver {
 public:
  static constexpr int kContactSlots = 4;  // = GR_MAX_PLANES (checked in solver.cpp)
  void substep(GrainsData& d, const GrainsSettings& s, const ColliderState* colliders,
               size_t collider_count, GrainsStats* stats = nullptr);
  // What one substep leaves for the next, at a frame's end (Node::save_state): the neighbour
  // rows kept for Verlet reuse and how they were built, the contact history, rigid shape
  // matching's components and rest shapes, the loads gauss_seidel's contacts ended with. The
  // rest is scratch, rebuilt in every substep or, like gauss_seidel's contact list, kept while
  // what it was built from holds and rebuilt after a load_state (with the same result).
  void save_state(StateWriter& w) const;
  void load_state(StateReader& r);
  // substeps so far whose gauss_seidel contact list was the last substep's (seq_list_kept)
  size_t contact_lists_kept() const { return seq_lists_kept_; }
  // gauss_seidel's lists the OpenCL device built (gauss_seidel.cpp), and the last substep's list
  // (brought from the device when it is newer there)
  size_t contact_lists_built_on_device() const { return seq_lists_device_; }
  // use_opencl: the neighbour searches whose rows' indices stayed on the device (rows_stay)
  size_t rows_left_on_device() const { return rows_left_; }
  // the searches of rows at a substep's start (on either side, kept rows not counted), the
  // times rows left on the device came back (sync_rows), and the overlap statistics measured
  // along rows there (contact_stats)
  size_t rows_searched() const { return rows_searched_; }
  size_t rows_brought_back() const { return rows_brought_; }
  size_t overlaps_on_device() const { return overlaps_device_; }
  // use_opencl: the last substep's rows are those its device's search found (rows_on_device_)
  bool rows_from_device() const { return rows_on_device_; }
  // the last substep's number of row entries, and the most entries a row holds (with contacts'
  // friction), measured where they are: neither brings the rows from the device
  size_t candidate_entries() const {
    return candidates_on_ && !neighbors_.offsets.empty() ? neighbors_.offsets.back() : 0;
  }
  size_t longest_row() const { return rows_longest_; }
  // use_opencl with jacobi: the substeps so far whose contact history the device saved, and
  // those whose carried slips it looked up by id there (rather than finding them in place)
  size_t histories_saved_on_device() const { return hist_saved_device_; }
  size_t histories_looked_up_on_device() const { return hist_lookups_device_; }
  // ... and those whose collider planes' slips it saved, and those whose planes' carried slips
  // it made there from a save it kept (jacobi_planes_stay)
  size_t plane_histories_saved_on_device() const { return hist_plane_saved_device_; }
  size_t plane_histories_loaded_on_device() const { return hist_plane_loaded_device_; }
  // the last substep's number of collider plane entries (0 without colliders), where they are:
  // it brings no plane from the device
  size_t plane_entries() const { return plane_offsets_.size() > n_ ? plane_offsets_[n_] : 0; }
  const std::vector<gr_seq_contact>& contact_list() const {
    sync_contacts();
    return seq_;
  }
  // the pre-stabilization passes the last substep ran (either solver; 0 when it ran none)
  int stabilize_passes() const { return stabilize_passes_; }
  // The last substep's neighbour candidates (rows in the caller's grain order), or nullptr when
  // it searched none (no contacts and no clumping). Valid until the next substep.
  const NeighborList* candidates() const {
    if (!candidates_on_) return nullptr;
    sync_rows();
    return &neighbors_;
  }
  // The last substep's collider planes as the iterations last took them (kernels/planes.h):
  // each grain's first entry (n + 1; empty without colliders), the entries (9 floats each) and
  // their colliders. Valid until the next substep.
  struct PlaneRows {
    const std::vector<uint32_t>* offsets;
    const std::vector<float>* plane;
    const std::vector<int32_t>* collider;
  };
  PlaneRows collider_planes() const {
    sync_planes();
    return {&plane_offsets_, &plane_, &plane_collider_};
  }
  // use_opencl: the collider plane searches the device ran (planes.cpp)
  size_t planes_found_on_device() const { return planes_device_; }
  // The grains node's sleeping test's reads along the last substep's neighbour rows
  // (kernels/row_stats.h, gr_row_sleep), made on the device while the rows are there: each
  // grain's word into *out at the world positions P (not sent again when they are the positions
  // the substep wrote and !moved) with the substep's radii and a byte a grain, `fast`. False
  // where the host holds the rows, or a count does not fit its word: the caller then counts
  // along candidates() (nodes/grains/sleep_rows.h), which brings them.
  bool sleep_rows_on_device(const float* P, bool moved, const uint8_t* fast,
                            std::vector<uint32_t>* out);
  // the sleeping tests made on the device so far
  size_t sleep_rows_device() const { return sleep_rows_device_; }
  // Whether the device can make the grains node's whole sleeping test around a substep with
  // these settings and colliders (GrainsData::sleep): gauss_seidel's substep on the device,
  // ended there with its velocities (no host_finish), no global mass
  // shock, no mesh collider whose queries the host makes (meshes_here), a device with the rows'
  // kernels that builds the contact list, and no GRAINS_OPENCL_HOST_SLEEP=1.
  bool sleeps_on_device(const GrainsSettings& s, const ColliderState* colliders,
                        size_t collider_count);
  // whether the device holds the test's state of n grains, as the last substep left it, and
  // that state brought back (n, n x 3, n x 3, n; any null)
  bool sleep_state_there(size_t n) const {
    return n > 0 && sleep_state_n_ == n && device_.device != nullptr;
  }
  void fetch_sleep_state(float* time, float* anchor, float* accel, int32_t* contacts);
  // the substeps so far whose whole sleeping test the device made, and of those, the ones
  // whose state the node gave (not held there) and the device carried instead of taking it up
  // (the node's attributes as they came back, in the order the substep's start carried)
  size_t slept_on_device() const { return slept_device_; }
  size_t sleep_states_carried() const { return sleep_carried_; }
  // Error control's motion measure (engine/motion_need.h) of the end held on the device
  // (end_held()), made there with the masses (awake), radii and forces this substep read, added
  // into *worst and *fall; false where the device cannot. The forces as the device took them:
  // each grain's row (n x 3), or one row for all (*uniform); null: none.
  bool motion_on_device(double step, double fps, double* worst, double* fall);
  const float* device_forces(bool* uniform) const {
    *uniform = force_uniform_;
    return force_there_ ? (force_uniform_ ? force_row_ : end_force_.data()) : nullptr;
  }
  // the motion measures made on the device so far
  size_t motions_on_device() const { return motions_device_; }
  // use_opencl: what has crossed between the host and the device since the solver opened it
  // (opencl::Iterations::traffic; zero before)
  opencl::Traffic device_traffic() const;
  // whether the device ended the last substep (velocity update, SubstepEnd), whether
  // its final collision test ran there too (its planes found there), and how many grains the
  // host's final collision test moved after the device's end (their positions alone go up for
  // the overlap statistics)
  bool finished_on_device() const { return finished_there_; }
  bool collided_on_device() const { return collided_there_; }
  size_t finish_changed() const { return finished_there_ ? end_changed_.size() : 0; }
  // whether the last substep's start was made on the device from the end before (carry_start),
  // and how many grains went up for it
  bool carried_start() const { return carried_; }
  // use_opencl: whether the last substep's end stayed on the device (GrainsData::may_hold_end),
  // its positions and velocities not brought back, every one finite (measured there, with the
  // box that gives the next substep's origin); the next substep may start from it
  // (GrainsData::start_held)
  bool end_held() const { return device_.end_there; }
  // that end's world positions and velocities (n x 3), each brought back at its first call;
  // valid until the next substep
  const float* end_positions();
  const float* end_velocities();
  // the substeps so far that ended there (end_held), and those that started from such an end
  // and never brought it here (fetch_start)
  size_t held_ends() const { return held_ends_; }
  size_t held_starts() const { return held_starts_; }
  // whether the device made the last substep's predicted positions (predict)
  bool predicted_on_device() const { return predicted_there_; }
  // the substeps so far in which the host made the predicted positions too (host_p: a stage
  // read them here), and the Verlet tests of kept rows made on the device (keep_rows)
  size_t host_predictions() const { return host_predictions_; }
  size_t rows_tests_on_device() const { return rows_tests_device_; }
  size_t carried_changed() const { return carried_ ? carry_changed_.size() : 0; }
  // contact_solver gauss_seidel's contacts of the last substep in the order they are swept, in
  // blocks, colours and waves, as opencl::Iterations takes them (opencl/iterations.h); valid
  // until the next substep
  opencl::SequentialContacts contact_sweep();

 private:
  void check_state(const StateReader& r) const;  // load_state's checks of what it read
  bool candidates_on_ = false;
  void build_constraints(const GrainsData& d);
  // leaves out of neighbors_ every pair joined by an explicit constraint (con_offsets_ and
  // con_other_ built); keeps each row's order
  void drop_constrained_pairs(int threads);
  void update_constraints(GrainsData& d, const GrainsSettings& s, int threads, GrainsStats* stats);
  // the shape goals, then each component out of its collider planes and, with collider
  // friction, its contacts' slip taken out as a rigid body (g: the substep's inputs, for P, the
  // planes and the friction attribute), on p_ (kernels/shapes.h)
  void project_shapes(const gr_grains& g, const gr_params& prm, int threads);
  // the components, rest offsets, masses and (with collider friction) normal sums as the
  // shared functions read them
  gr_shapes shape_arrays(const gr_params& prm);
  // P, p in the substep's coordinates, world = those + origin (planes.cpp). device: found on
  // the OpenCL device (null: here; with a mesh only where !meshes_here); p_there: p is the
  // positions the device's search took, radius_there: radius_ its radii
  // entries_stay: the host reads no entry this substep but through sync_planes (a gauss_seidel
  // list the device builds, no impact data, no rigid shapes; or jacobi_planes_stay)
  struct DevicePlanes {
    bool p_there = false, radius_there = false, entries_stay = false, rows_stay = false;
  };
  void find_planes(const float* P, const float* p, const Vec3& origin,
                   const ColliderState* colliders, size_t collider_count, float query_scale,
                   int threads, const DevicePlanes* device);
  // whether one of the colliders is a mesh
  static bool any_mesh(const ColliderState* colliders, size_t count);
  // whether one of the colliders is a mesh whose queries (its planes, final collision test,
  // impact data and sleepers' wake) the host makes: use_opencl off, a device without double
  // precision (engine/mesh_query.h), or host_mesh
  bool meshes_here(const GrainsSettings& s, const ColliderState* colliders, size_t count);

  struct SubstepContext;  // the substep's stages' (solver.cpp)

  // contact history (friction anchors): each contact's slip its friction has not yet removed,
  // carried to the next substep by the grains' ids (GrainsData::id) so that a contact keeps
  // pulling back to where it stuck until it slides
  // use_opencl (`device`: the substep's context): the pairs' slips are saved and loaded on the
  // device where its search's rows are (opencl/history.cpp), the same floats
  void load_history(const GrainsData& d, bool pairs, bool planes, bool same_rows, int threads,
                    const SubstepContext* device);
  void save_history(const GrainsData& d, const GrainsSettings& s, const gr_grains& g,
                    const gr_params& prm, const float* p, bool pairs, bool planes, int threads,
                    const SubstepContext* device);
  int32_t previous_index(int32_t id) const;
  // whether the last substep's ids (hist_id_) can be looked up, none below 0 and none far above
  // n; *top: the largest
  bool history_ids(size_t n, int32_t* top) const;

  // the substep's stages (solver.cpp)
  void build_shapes(const GrainsData& d);
  // device: the substep's context when its passes run on the OpenCL device (use_opencl)
  void pre_stabilize(const gr_grains& g, const gr_params& prm, bool pairs, int iterations,
                     int threads, const SubstepContext* device);
  void write_back(GrainsData& d, const GrainsSettings& s, const gr_grains& g, const gr_params& prm,
                  const ColliderState* colliders, size_t collider_count, const Vec3& origin,
                  bool impacts, int threads);
  void contact_stats(const GrainsData& d, GrainsStats* stats) const;

  // stages over one substep's context (solver.cpp): the kernels' inputs, the prediction, the
  // sums and search settings the substep opens with, the neighbour rows and collider planes
  // (first: at the substep's start; otherwise a rebuild during the iterations, carrying what they
  // accumulated), the iterations with their friction passes and pins
  void bind_inputs(SubstepContext& c);
  void predict(SubstepContext& c);
  // p_: this substep's predicted positions, made here the first time the host reads them
  // (predict), or the positions a later stage wrote there
  float* host_p(const SubstepContext& c);
  float* p_for_device(const SubstepContext& c, bool there);
  void open_sums(SubstepContext& c);
  void open_search(SubstepContext& c);
  bool keep_rows(const SubstepContext& c);
  void find_pairs(SubstepContext& c, bool first);
  void update_planes(SubstepContext& c, bool first);
  void iterate(SubstepContext& c);
  void gauss_seidel(SubstepContext& c);
  void run_friction(SubstepContext& c);
  void project_pins(SubstepContext& c);
  void device_passes(SubstepContext& c, float* x, int count, bool friction_after, bool whole,
                     const opencl::JacobiSolve* w = nullptr);
  opencl::SubstepEnd* finish_there(const SubstepContext& c, opencl::SubstepEnd* end);
  bool jacobi_on_device(const SubstepContext& c);
  opencl::Iterations& open_device();
  opencl::IterationSizes device_sizes(const SubstepContext& c) const;

  // Verlet reuse of the neighbour rows across substeps (keep_rows)
  void remember_rows(const GrainsData& d, const GrainsSettings& s, const float* search_radius,
                     const float* p, int threads);

  // the iterations on an OpenCL device (use_opencl), opened at the first substep that asks; a
  // copy of the solver opens its own. holds_contacts: the device holds the contact list from its
  // last call (a copy's device holds nothing); stale: the host's copy of it (seq_, seq_loads_)
  // is older, the device's list ending with `loaded` normal loads, and sync_contacts() brings
  // it. So may the neighbour rows (rows_stale: their offsets but the last, and their indices):
  // the device's search left them there and the substep read them nowhere else (rows_stay),
  // sync_rows() brings them; and the positions they were built from (rows_p_stale,
  // sync_rows_p()). A copy or move of the solver brings all of these first: declared before
  // neighbors_, rows_p_, seq_ and seq_loads_, the slot is copied before them, and its copy and
  // move call owner->sync_device() (owner: the solver whose substep last ran, set there; stale
  // only after one)
  struct DeviceSlot {
    std::unique_ptr<opencl::Iterations> device;
    bool holds_contacts = false;
    bool stale = false;
    bool rows_stale = false;
    bool planes_stale = false;  // plane_'s entries are the device's (find_planes' entries_stay)
    // plane_offsets_ (but its last element) and plane_collider_ are the device's (rows_stay)
    bool plane_rows_stale = false;
    // rows_p_ (the positions the kept rows were built from) is the device's: the search there
    // took them, and its Verlet test reads them there (keep_rows)
    bool rows_p_stale = false;
    // the last end stayed there (end_held()); end_P_ and end_v_ are the device's until brought
    // back (end_positions(), end_velocities())
    bool end_there = false, end_P_stale = false, end_v_stale = false;
    // the Jacobi path's contact history (save_history, load_history): hist_slip_ is the slips
    // the device saved; pair_slip_ is the carried slips it made; slips_there: the device holds
    // pair_slip_ (it made them, or a call of this substep sent them)
    bool hist_stale = false, slips_stale = false, slips_there = false;
    // ... and of the collider planes (jacobi_planes_stay): hist_planes_stale, the device kept
    // the last save (hist_plane_offsets_, hist_plane_collider_ and hist_plane_slip_ are older);
    // plane_slips_stale, it made plane_slip_ and holds collider_normal_, the host's older
    bool hist_planes_stale = false, plane_slips_stale = false;
    // the Jacobi path's pair sums (pair_normal_): sums_there, the device holds them from the
    // substep's last call; sums_stale, the host's are older (they stayed there)
    bool sums_there = false, sums_stale = false;
    // the device holds the friction each grain received (friction_dx_, which stays there)
    bool friction_there = false;
    // p_ is what the device's whole-substep Jacobi call ended with, unchanged since: the
    // contact history's save takes it there (save_history)
    bool p_there = false;
    size_t loaded = 0;
    const GrainsSolver* owner = nullptr;
    DeviceSlot();
    ~DeviceSlot();
    DeviceSlot(const DeviceSlot&);
    DeviceSlot& operator=(const DeviceSlot&);
    DeviceSlot(DeviceSlot&&);
    DeviceSlot& operator=(DeviceSlot&&);
  };
  DeviceSlot device_;
  // use_opencl: neighbors_ holds the rows the device's last search gave, unchanged (kept across
  // substeps with them), which the device's contact list build and solve then read where they are
  bool rows_on_device_ = false;
  // this substep's predicted positions p_ went to the device with its search of rows or
  // planes, or the device made them (predicted_there_), unchanged since (the search, the planes
  // and the solve then copy them there rather than sending them again); searched_there_: the
  // device's search of rows took them this substep (and the radii with them)
  bool p_on_device_ = false, predicted_there_ = false, searched_there_ = false;
  // p_ holds this substep's predicted positions (host_p), or what a later stage wrote there
  bool p_made_ = false;
  size_t host_predictions_ = 0,
         rows_tests_device_ = 0;  // host_predictions(), rows_tests_on_device()
  // the written positions (d.P) error control's statistics sent to the device this substep
  mutable const float* written_on_device_ = nullptr;
  // gauss_seidel's device solve ended the substep there (SubstepEnd): each grain's
  // written position (world) and velocity in end_P_ and end_v_ (n x 3), which write_back takes
  // for its own; the device keeps those positions, and write_back lists in end_changed_ the
  // grains its final collision test moved, which contact_stats and the sleeping test send alone;
  // collided_there_: the final collision test ran there too (kernels/final_collision.h), on the
  // colliders the device's planes took (with their meshes), unless the start velocity is kept
  bool finished_there_ = false, collided_there_ = false;
  // use_opencl: the substep's start positions (P0_) and velocities (d.v) made on the device from
  // what the last end there wrote (end_P_ and end_v_ hold the same floats), but for the grains
  // whose host values differ (carry_changed_), which go up alone; carried_: it was
  void carry_start(const SubstepContext& c);
  bool carried_from_ = false;  // carry_start sent carry_from_: the grains in another order
  bool carried_ = false;
  // this substep's start is the end the device held (GrainsData::start_held), which d.P and
  // d.v do not hold: start_stays() says whether every stage reads it there, fetch_start()
  // brings it into d.P and d.v (and P0_) for one that does not; end_origin_: the origin the
  // held end's box gives (local_origin's); end_stays_: the device's end of this substep stays
  // there (SubstepEnd::stay), which write_back keeps when every grain is finite
  bool start_held_ = false, end_stays_ = false;
  // pre-stabilization ran this substep; on the device, where the start and the prediction it
  // moved stay (the Jacobi chain there: jacobi_on_device)
  bool stabilized_ = false, stable_there_ = false;
  Vec3 end_origin_;
  size_t held_ends_ = 0, held_starts_ = 0;
  bool start_stays(const GrainsData& d, const GrainsSettings& s, const ColliderState* colliders,
                   size_t collider_count);
  void fetch_start(const SubstepContext& c);
  std::vector<uint8_t> carry_differs_;
  std::vector<gr_uint> carry_changed_;
  // the ids of the grains the last end there wrote (its order), and each grain's index there
  // when the grains come in another order (find_in_end; kNotInEnd: not there), with its table
  static constexpr gr_uint kNotInEnd = 0xffffffffu;
  std::vector<int32_t> end_ids_;
  std::vector<gr_uint> carry_from_, carry_at_;
  void find_in_end(const int32_t* id, size_t n);
  const float* finish_P_ = nullptr;  // the written positions' array (d.P) write_back filled
  // g's force as the device reads it (its prediction and end; SubstepContext::device_force):
  // null (none), one row that every grain reads (*uniform), else a copy of each grain's row
  // (end_force_)
  const float* device_force(const gr_grains& g, bool* uniform);
  std::vector<float> end_P_, end_v_, end_force_;
  std::vector<gr_uint> end_changed_;
  std::vector<uint8_t> end_hit_;
  size_t sleep_rows_device_ = 0;  // sleep_rows_device()
  // the sleeping test made on the device this substep (GrainsData::sleep; sleep_begin before
  // the prediction, sleep_end in write_back), and in the last; whether a grain sleeps now that
  // did not then, or the reverse (gauss_seidel's list is then built again: the inverse masses
  // the host compares are the grains' awake); the grains of the state there
  bool sleep_there_ = false, slept_there_ = false, sleep_changed_ = false;
  gr_sleep_params sleep_params_{};
  size_t sleep_state_n_ = 0, slept_device_ = 0, motions_device_ = 0, sleep_carried_ = 0;
  // the state the device's last sleep_end left, as it came back (fetch_sleep_state), each of
  // the four arrays whole (time, anchor, accel, contacts) or empty: what the node's attributes
  // are where nothing wrote them since, which the device then carries (carry_sleep)
  std::vector<float> sleep_back_time_, sleep_back_anchor_, sleep_back_accel_;
  std::vector<int32_t> sleep_back_contacts_;
  bool carry_sleep(const GrainsSleep& z);
  // the force the device read this substep (device_forces): any, one row for all (a copy here)
  bool force_there_ = false, force_uniform_ = false;
  float force_row_[3] = {0, 0, 0};
  void sleep_begin(SubstepContext& c);
  // the device's rows were searched with the grains' own radii (not assume_uniform_radius's)
  bool rows_true_radius_ = false;
  size_t rows_left_ = 0;
  // Rows left on the device cost what a read along them there sends: the positions, where the
  // device holds none of those read (the host's end of the substep; 12 B a grain). read_rows()
  // counts it for each read, made there or here, since the last search (rows_read_sent_), and
  // brings the rows once it would pass what they take to bring (rows_bytes_: 4 B a grain and an
  // entry); a search leaves them there unless the reads since the last one sent more than those
  // rows took (find_pairs). So a substep's reads send at most what fetching the rows would, and
  // rows kept for many substeps come back once, as they did before they stayed.
  mutable size_t rows_read_sent_ = 0, rows_brought_ = 0, overlaps_device_ = 0;
  size_t rows_searched_ = 0;
  size_t rows_bytes_ = 0;
  bool read_rows(bool sends_positions) const;
  // the device holds this substep's collider planes (find_planes): they do not go up again;
  // plane_rows_there_: their rows and colliders stayed there too (gauss_seidel's list built
  // there), where the device compared them with those of the list, kept there when it was
  // built (seq_planes_there_): planes_same_ says whether they are the same
  bool planes_on_device_ = false, plane_rows_there_ = false, planes_same_ = false;
  // ... and they stay there for the Jacobi path's history and passes (jacobi_planes_stay)
  bool planes_kept_there_ = false;
  // neighbors_'s offsets and indices from the device (DeviceSlot::rows_stale), plane_'s entries
  // (DeviceSlot::planes_stale), the planes' rows and colliders (DeviceSlot::plane_rows_stale),
  // and all of these with the contact list
  void sync_rows() const;
  // hist_slip_ and pair_slip_ from the device (DeviceSlot::hist_stale, slips_stale), and the
  // planes' history (hist_planes_stale), carried slips and sums (plane_slips_stale)
  void sync_history() const;
  void sync_pair_history() const;
  void sync_plane_history() const;
  void sync_plane_slips() const;
  void sync_slips() const;
  void sync_sums() const;  // pair_normal_ from the device (DeviceSlot::sums_stale)
  void sync_rows_p() const;
  void sync_planes() const;
  void sync_end(bool positions, bool velocities) const;  // end_P_, end_v_ (DeviceSlot)
  void sync_device() const;
  // whether this substep's rows may stay on the device: it reads them nowhere else
  bool rows_stay(const SubstepContext& c) const;
  // use_opencl with jacobi: the iterations are one device call, nothing between them here (no
  // rigid shapes projected here, no rows or planes found again during them but there:
  // rebuilds_there; Chebyshev's step made there)
  bool jacobi_whole(const SubstepContext& c) const;
  static bool jacobi_loop_there(const GrainsSettings& s, bool rebuilds = false);
  bool rebuilds_there(const SubstepContext& c);
  bool rebuilds_fit(const SubstepContext& c);
  bool rebuilds_chain(const GrainsSettings& s);
  // the shapes as a device projects them (shape_arrays), into *out
  const opencl::ShapeArrays* shape_arrays_there(const SubstepContext& c, opencl::ShapeArrays* out);
  // ... and this substep's collider planes may stay there: no stage here reads them (no impact
  // data, the contact history made there)
  bool jacobi_planes_stay(const SubstepContext& c) const;
  NeighborSearch search_;
  NeighborList neighbors_;
  // the rows' build: valid, for these grains (ids) and radii, from these predicted positions,
  // with these search settings; skin (m): how far apart from touching a pair left out was
  bool rows_valid_ = false;
  float rows_skin_ = 0, rows_query_scale_ = 0;
  int rows_max_ = 0;
  bool rows_uniform_ = false;
  std::vector<int32_t> rows_ids_;
  std::vector<float> rows_radius_, rows_p_;
  // scratch, reused between substeps (n = grains this substep)
  std::vector<float> p_, p_next_;   // (n x 3) m: the Jacobi iterates
  std::vector<float> p_before_;     // (n x 3) m: the iterate before p_ (Chebyshev only)
  // P at the start of the substep, minus the substep's origin (local_origin in solver.cpp):
  // the caller's P itself when that origin is 0, else P0_ (n x 3, m); explicit constraints
  // always take the copy, because their strain update reads it after P is overwritten
  const float* P0_ = nullptr;
  std::vector<float> P0_copy_;
  std::vector<float> target_local_;  // (n x 3) m: targetP minus that origin, when it is not 0
  // accumulated contact overlaps bounding the friction pass (gr_friction_pass)
  std::vector<uint32_t> pair_normal_;  // (neighbour entries) m, as float bits
  std::vector<float> pair_normal_it_;  // (threads x row_stride_) m: this iteration's overlaps
  size_t row_length_ = 1;              // the longest neighbour row, in whole blocks of lanes
  // the longest neighbour row's entries (rows_longest_) measured since the rows were built
  bool longest_known_ = false;
  size_t rows_longest_ = 0;
  size_t row_stride_ = 1;              // floats between threads' rows in pair_normal_it_
  // pre-stabilization: start positions with the overlaps they began with removed (g.P after it)
  static constexpr float kStabilizeTolerance = 0.002f;  // of a grain's radius
  static constexpr int kStabilizeIterations = 64;  // and at most constraint_iterations
  std::vector<float> P_stable_, p_stable_next_;  // (n x 3 + 1) m
  // contact_solver gauss_seidel (gauss_seidel.cpp): this substep's contacts, and the loads the
  // last substep's contacts ended with, by key (sorted), for the warm start
  using SeqContact = gr_seq_contact;  // kernels/sequential.h
  static_assert(sizeof(SeqContact) == 56, "the OpenCL device reads the same bytes");
  struct SeqLoad {
    uint64_t key;
    float ln;
    float lt[3];
  };
  std::vector<SeqContact> seq_;
  size_t seq_count_ = 0;  // the list's length (seq_'s, or the device's when it built the list)
  // the host's copy of a list the device has newer (DeviceSlot::stale), and its loads
  void sync_contacts() const;
  // seq_loads_ from seq_'s normal loads, indexed by key
  void store_loads();
  std::vector<SeqContact> seq_row_;  // one grain's contacts as gr_seq_build writes them
  // seq_ in blocks of grains, the blocks in colours (colour_blocks): block b's contacts are
  // seq_[block_start_[b], block_start_[b + 1]); colour c's blocks are
  // colour_blocks_[colour_start_[c], colour_start_[c + 1]), ascending
  std::vector<uint32_t> block_start_, colour_blocks_, colour_start_;
  std::vector<uint64_t> block_links_;  // linked blocks (lower << 32 | higher), each once
  std::vector<uint32_t> block_linked_;  // (blocks) the last lower block + 1 linked to each
  std::vector<uint32_t> block_link_start_, block_link_to_;
  std::vector<int32_t> block_colour_;
  // colour_blocks: block_start_ and block_links_ from seq_, then colour_linked_blocks()
  void colour_blocks();
  void colour_linked_blocks();
  // each block's contacts in waves that share no moving grain (order_waves): block b's waves
  // are block_wave_[b] to block_wave_[b + 1], wave w's contacts seq_[wave_start_[w],
  // wave_start_[w + 1])
  std::vector<uint32_t> block_wave_, wave_start_;
  std::vector<gr_ulong> wave_marks_;                // 2 a grain: the waves 0-127 it is in
  std::vector<std::vector<uint32_t>> block_waves_;  // a block's waves' starts within it
  std::vector<SeqContact> wave_block_;              // a block's contacts, a copy per thread
  std::vector<uint32_t> wave_of_;                   // their waves
  bool seq_waves_ = false;                          // seq_ is in waves
  void order_waves(int threads, bool waves);
  // seq_ and its blocks are kept for the next substep when everything they were built from is
  // the same (seq_list_kept): the neighbour rows (kept by keep_rows), the collider planes, and
  // each grain's inverse mass, repulsion scale and friction (seq_grain_, 3 a grain; this
  // substep's in seq_grain_now_) under the same friction scales; seq_valid_ says seq_ holds the
  // last substep's list
  bool seq_valid_ = false;
  size_t seq_lists_kept_ = 0, seq_lists_device_ = 0;
  int stabilize_passes_ = 0;  // stabilize_passes()
  std::vector<float> seq_grain_, seq_grain_now_;
  std::vector<gr_uint> seq_plane_offsets_;
  std::vector<int32_t> seq_plane_collider_;
  bool seq_planes_there_ = false;  // the device keeps the list's planes instead (keep_planes)
  float seq_friction_[2] = {0, 0};
  bool seq_list_kept(const SubstepContext& c, bool pairs, const std::vector<float>& grain) const;
  std::vector<SeqLoad> seq_loads_;
  float seq_dt_ = 0;  // the substep the loads were built in
  // seq_loads_ by key: an open-addressed table of indices + 1 (0: empty), a power of two long
  std::vector<uint32_t> seq_table_;
  int seq_table_bits_ = 0;
  void index_loads();
  const SeqLoad* find_load(uint64_t key) const;
  // this substep's contacts' carried loads (seq_loads_ index + 1, 0: none), and what the
  // carried contacts' pre-stabilization moved each grain (3 a grain)
  std::vector<uint32_t> load_of_;
  std::vector<float> carried_move_;
  std::vector<uint8_t> loaded_;  // use_opencl: 1 for a contact with a carried load
  // the warm start's per-contact and per-grain working arrays, kept between substeps
  std::vector<float> warm_factor_, warm_balance_;
  std::vector<float> warm_normal_, warm_repeat_, warm_external_;  // 3 a contact, 3 a grain
  std::vector<uint8_t> warm_cold_;
  std::vector<float> friction_dx_;  // (n x 3) m: friction received this substep (accurate)
  // the history saved at the end of the last substep, by grain in that substep's order: the id
  // of each grain, a slip per entry of its neighbour rows (hist_rows_ holds those rows once
  // they are rebuilt), and per grain a row of (collider, slip)
  size_t hist_saved_device_ = 0, hist_lookups_device_ = 0;  // histories_saved_on_device() ...
  size_t hist_plane_saved_device_ = 0, hist_plane_loaded_device_ = 0;
  std::vector<float> plane_saved_;  // (plane entries x 3) m: each entry's slip, before the cut
  std::vector<int32_t> hist_id_;
  std::vector<int32_t> hist_lookup_;  // id -> index into hist_id_ (-1: none), ids >= 0
  NeighborList hist_rows_;
  std::vector<uint32_t> hist_plane_offsets_;
  std::vector<int32_t> hist_plane_collider_;
  std::vector<float> hist_slip_, hist_plane_slip_;  // (entries x 3) m
  std::vector<float> pair_slip_;   // (neighbour entries x 3) m: this substep's, from the history
  std::vector<float> plane_slip_;  // (plane entries x 3) m
  std::vector<uint32_t> row_kept_;     // (n) entries each row keeps, in drop_constrained_pairs
  // accumulated collider overlaps for the friction pass (no accurate friction), per plane entry
  std::vector<float> collider_normal_;  // (plane entries) m
  // the planes before a rebuild during the iterations, to carry those sums
  std::vector<uint32_t> prev_plane_offsets_;
  std::vector<int32_t> prev_plane_collider_;
  std::vector<float> prev_collider_normal_;
  NeighborList prev_neighbors_;  // rows before a rebuild during the iterations, to carry sums
  std::vector<float> search_radius_;  // (n) m: the largest radius, with assume_uniform_radius
  // (n) m: the caller's pscale, or radius_copy_ = particle_separation / 2 when it has none
  const float* radius_ = nullptr;
  std::vector<float> radius_copy_;
  // (n) kg: the caller's mass, or mass_copy_ = 1 when it has none
  const float* mass_ = nullptr;
  std::vector<float> mass_copy_;
  size_t n_ = 0;                    // grains this substep
  std::vector<float> inv_mass_;     // (n) 1/kg: 1/mass, or 1/shockmass (global mass-shock)
  // collider planes, a compact row per grain (at most GR_MAX_PLANES, nearest first)
  std::vector<uint32_t> plane_offsets_;  // (n + 1)
  std::vector<float> plane_;             // (entries x 9): surface point, normal, velocity
  size_t planes_device_ = 0;             // planes_found_on_device()
  std::vector<int32_t> plane_collider_;  // (entries): collider index of each plane
  std::vector<gr_collider> plane_colliders_;  // the substep's colliders (find_planes)
  std::vector<std::shared_ptr<const MeshShape>> device_meshes_;  // and their meshes (there)
  // explicit constraints: per-grain rows of (other endpoint, primitive), rebuilt each substep
  std::vector<uint32_t> con_offsets_;      // (n + 1)
  std::vector<uint32_t> con_other_, con_prim_;  // (2 m)
  std::vector<uint32_t> degree_;           // (n) scratch: constraint degree (remove strands)
  std::vector<uint8_t> dead_;              // (m) scratch when the caller gives no prim_dead
  std::vector<float> collider_dx_;  // (n x GR_MAX_PLANES x 3) m: applied collider corrections
  // rigid shape matching: components of the edge graph, rest offsets, per-iteration goals
  std::vector<int32_t> shape_key_;     // ids then edges (as ids) the rest shapes were built for
  uint64_t shape_generation_ = 0;      // counts the rest shapes built or read (a device's copy)
  std::vector<uint32_t> comp_offsets_;  // (components + 1) rows into comp_members_
  std::vector<uint32_t> comp_members_;  // grains of each component (components of 2 or more)
  std::vector<float> rest_offset_;      // (n x 3) m: rbar_i, i's rest offset from its centre
};

}  // namespace grains
