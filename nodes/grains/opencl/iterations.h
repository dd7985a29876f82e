// The parts of the substep an OpenCL device runs (a grains node with use_opencl): the neighbour
// rows (find_neighbours()) and what the host reads along them (row_overlaps(), row_reach()),
// the collider planes (find_planes()), the Jacobi path's pre-stabilization (stabilize()),
// iterations and friction passes (run()), and contact_solver gauss_seidel's list
// (build_sequential()) and its solve from its contacts on (solve_sequential():
// pre-stabilization, the velocity it takes back, the warm start, the passes and the velocity
// update; run_sequential() for passes alone), and the grains node's sleeping test around a
// substep (sleep_begin(), sleep_end(); opencl/sleep.cpp). GrainsSolver::substep does the rest on
// the CPU (prediction, a mesh collider's planes, contact history, the contact list where the device
// does not build it; the Jacobi path's velocity update, final collisions, history, strain) and
// hands each call its inputs. The kernels call the functions the CPU loops call (kernels/,
// engine/pair_test.h, engine/collider_shape.h; grains.cl). Each per-grain work-item writes only its
// own grain and sums in row order; each Gauss-Seidel work-group sweeps one block of contacts wave
// by wave, its work-items sharing a wave, no two blocks at once and no two contacts of a wave
// writing one grain; integer atomics only count: a device gives the same result run to run, the
// CPU's sweep's in the same order.
#pragma once
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "engine/collider_shape.h"
#include "engine/neighbors.h"
#include "nodes/grains/kernels/iterate.h"
#include "nodes/grains/kernels/sequential.h"
#include "nodes/grains/kernels/sleep.h"

namespace grains {
class MeshShape;
}

namespace grains::opencl {

// How much of each array run() reads: grains, neighbour entries, collider plane entries,
// explicit-constraint primitives, and the row scratch of the contact loop.
struct IterationSizes {
  size_t n = 0;
  size_t pair_entries = 0;
  size_t plane_entries = 0;
  size_t prims = 0;
  size_t row_length = 0;  // floats of one grain's overlap row (whole blocks of GR_LANES)
  // the device holds the substep's collider planes as its find_planes() left them: the plane
  // rows, entries and colliders do not go up again
  bool planes_there = false;
  // the device's last neighbour search found the rows (g's nbr_offsets and nbr_indices, as it
  // gave them): they do not go up, the device copies them where the solve reads them
  bool rows_there = false;
  // the device holds g.pair_slip: it made them (load_pair_history) or a call of this substep
  // sent them, and the host has not changed them since
  bool slips_there = false;
  // the device holds the pair sums (the last call's): run() does not send acc.pair; sums_stay:
  // run() does not bring them back either (fetch_pair_sums() does)
  bool sums_there = false, sums_stay = false;
  // the device holds the friction each grain received this substep (acc.friction_dx), from the
  // substep's last call: run() does not send it
  bool friction_there = false;
  // the device holds g.plane_slip (load_plane_history made them): run() does not send them;
  // collider_sums_stay: run() does not bring the collider sums (acc.collider) back
  bool plane_slips_there = false, collider_sums_stay = false;
};

// Rigid shape matching on the device (kernels/shapes.h, gr_k_shapes, a work-group a
// component), on a device with double precision (Iterations::shapes_there()): `components`
// components of offsets (components + 1) and members, each grain's rest offset (3 n) and mass
// (n), and, when set, the collider planes' normal sums (a float an entry of g's planes,
// `entries`; with gauss_seidel sent and brought back each call, with jacobi the iterations'
// collider sums, acc.collider, which the device holds). generation (above 0): the components
// and rest offsets are those the last call of the same generation sent, which stay there (mass
// goes up once a substep).
struct ShapeArrays {
  const gr_uint* offsets = nullptr;
  const gr_uint* members = nullptr;
  size_t components = 0;
  const float* rest = nullptr;
  const float* mass = nullptr;
  uint64_t generation = 0;
  float* collider_normal = nullptr;
  size_t entries = 0;
};

// contact_solver gauss_seidel's contacts in blocks and colours (GrainsSolver::colour_blocks)
// and waves (GrainsSolver::order_waves): block b's contacts are contacts[block_start[b],
// block_start[b + 1]), colour c's blocks colour_blocks[colour_start[c], colour_start[c + 1]);
// block b's waves are block_wave[b] to block_wave[b + 1], wave w's contacts
// contacts[wave_start[w], wave_start[w + 1]), no two of them moving one grain; `others` (with
// others_prm) the explicit constraints and clumping, one Jacobi group before each pass, null
// when there are none
struct SequentialContacts {
  gr_seq_contact* contacts = nullptr;  // in and out: each contact's loads
  size_t count = 0;
  const gr_uint* block_start = nullptr;
  size_t blocks = 0;
  const gr_uint* colour_blocks = nullptr;
  const gr_uint* colour_start = nullptr;
  size_t colours = 0;
  const gr_uint* block_wave = nullptr;
  const gr_uint* wave_start = nullptr;
  size_t waves = 0;
  // resident: the device holds these contacts, blocks and waves as its last call left them
  // (the host's copy came back from there). solve_sequential() then uploads none of them and
  // keeps each contact's load there (gr_seq_keep with keep_warm and keep_scale; the loaded
  // flags are its results, SequentialSolve::loaded is not read)
  bool resident = false;
  bool keep_warm = false;
  float keep_scale = 0.0f;
  float relax = 1.0f;  // over_relaxation
  // built: the contacts are on the device already, in one part, each with its carried load and
  // flag (build_sequential; keep_warm says whether any was looked up): only the blocks, colours
  // and waves go up
  bool built = false;
  // stay: the contacts stay on the device after the solve, the host's copy is not written
  // (fetch_contacts brings them when the host needs them); *loaded (when set) receives how many
  // of them end with a normal load
  bool stay = false;
  size_t* loaded = nullptr;
  // run_sequential() only: the contacts, their blocks and waves and g's arrays are on the device
  // as the last call left them (with `stay`): only p goes up (and, with `stay`, the contacts
  // stay there after the passes too)
  bool there = false;
  const gr_grains* others = nullptr;
  const gr_params* others_prm = nullptr;
  // rigid shape matching after each pass's contacts and before its pins (ShapeArrays; null:
  // none)
  const ShapeArrays* shapes = nullptr;
};

// The substep's end on the device after its passes (gr_k_finish: gr_update_velocity; run() and
// solve_sequential()), instead of bringing back p, the pre-stabilized start and the velocities:
// each grain's written position, in world coordinates (the substep's plus origin, as
// GrainsSolver::write_back adds them), into P_out and, when v_out is set, its velocity (3 n floats
// each; with keep_velocity the start's, as the device holds them, and not gr_update_velocity's).
// force: gr_grains' force as the device reads it, a row a grain (3 n floats) or, with
// force_uniform, one row for every grain; null: none. The written positions stay there for
// row_overlaps() (written_there). With `colliders` (collider_count colliders, the array
// the substep's find_planes() took, and v_out) the final collision test follows there
// (gr_k_final_collision), from the start as it went up.
struct SubstepEnd {
  float* P_out = nullptr;
  float* v_out = nullptr;
  bool keep_velocity = false;
  const float* force = nullptr;
  bool force_uniform = false;
  float origin[3] = {0.0f, 0.0f, 0.0f};
  const gr_collider* colliders = nullptr;
  size_t collider_count = 0;
  // what it wrote stays there, P_out and v_out unwritten until fetch_end() brings them (v_out
  // still says whether the velocities are written)
  bool stay = false;
  // the impact data made there (gr_k_final_collision, kernels/impact.h) from gauss_seidel's
  // contacts' loads or jacobi's sums of the planes' moves and what the final collision test did,
  // into these (GR_MAX_PLANES slots a grain each, GrainsData's impact arrays; null: none),
  // which come back even where the end stays
  int32_t* impact_collider = nullptr;
  float* impact_impulse = nullptr;
  float* impact_normal = nullptr;
  float* impact_point = nullptr;
};

struct SequentialSolve {
  // pre-stabilization (gr_seq_stabilize) of the start positions and p, pass after pass while
  // go_on(pass, the pass's largest move) says so, at most `most` passes; x (3 n floats, out
  // only, null: none) receives the pre-stabilized start, which begins on the device as a copy
  // of g.P there
  float* x = nullptr;
  int most = 0;
  std::function<bool(int, float)> go_on;
  // a byte a contact, 1 when it carries a load (waiting in its accumulators, scaled to this
  // substep): the warm start runs when set (kernels/warm.h)
  const uint8_t* loaded = nullptr;
  // p_there: p (as it comes in) is the positions the substep's last find_neighbours() or
  // find_planes() took, which are copied there rather than sent again
  bool p_there = false;
  // take_back: what the loaded contacts' pre-stabilization moved each grain is summed on the
  // device (from zero, there), and the velocity it made taken back from v (3 n floats, in and
  // out; gr_warm_take_back, 1 / dt_last inv_last)
  bool take_back = false;
  float* v = nullptr;
  float inv_last = 0.0f;
  const SubstepEnd* finish = nullptr;
};

// run()'s positions and end on the device. p_there: p (as it comes in) is the positions the
// device holds (holds_prediction(): its prediction as a search or the planes took it, or as
// stabilize() moved it there), copied there rather than sent. finish: the substep's end there
// after the passes (SubstepEnd, with the final collision test from the start as it
// went up), p then not brought back.
struct JacobiSolve {
  bool p_there = false;
  const SubstepEnd* finish = nullptr;
  // above 0: Chebyshev's step after each iteration (kernels/iterate.h, gr_chebyshev_omega with
  // this rho), made there
  float chebyshev_rho = 0.0f;
  // rigid shape matching after each iteration and after each friction pass, before the pins
  // (ShapeArrays, its normal sums acc.collider; null: none)
  const ShapeArrays* shapes = nullptr;
  // set: the rows or planes found again before each iteration but the first
  // (update_*_during_iterations), there. It is called with the iterate as the positions the
  // searches take where they are (their p_there), makes its calls (find_neighbours() with
  // the rows staying and carry_pairs(); hold_planes(), find_planes() with rows and entries
  // staying, and carry_planes()) and rewrites g, size and acc for the rows and planes it
  // found: their host arrays sized as the host sizes them, their contents there. run() then
  // takes them there; nothing but what those calls bring back crosses.
  std::function<void(gr_grains* g, IterationSizes* size, gr_normal_sums* acc)> rebuild;
};

// What crosses between the host and the device: bytes each way, and the transfers that carried
// them (a copy or a fill on the device is neither)
struct Traffic {
  uint64_t sent = 0, received = 0;
  uint64_t uploads = 0, downloads = 0;
};

class Iterations {
 public:
  // Opens the device chosen_device() names and builds the program there; throws
  // std::runtime_error saying why when it cannot.
  Iterations();
  ~Iterations();
  Iterations(const Iterations&) = delete;
  Iterations& operator=(const Iterations&) = delete;

  // `iterations` Jacobi iterations of p (3 n + 1 floats, in and out) with g's arrays and prm,
  // then the friction pass: after every iteration when `accurate_friction`, else once after
  // them; none when !friction_pass. acc's sums (pair, collider, collider_dx, friction_dx: host
  // arrays, each null when unused) are read as they start and written back as they end, but
  // for those the device holds (size.sums_there, friction_there) and keeps (sums_stay; the
  // friction each grain received, which no host stage reads, never comes back); w: p there,
  // and the substep's end there.
  void run(const gr_grains& g, const gr_params& prm, const IterationSizes& size, float* p,
           const gr_normal_sums& acc, int iterations, bool friction_pass, bool accurate_friction,
           const JacobiSolve& w = JacobiSolve());

  // `iterations` passes of contact_solver gauss_seidel on p (3 n + 1 floats, in and out): each
  // the others' Jacobi group, then the contacts colour by colour, then the pins (g.targetP);
  // s.contacts in and out, unless s.there and s.stay keep them on the device
  void run_sequential(const gr_grains& g, const gr_params& prm, const IterationSizes& size, float* p,
                      const SequentialContacts& s, int iterations);

  // The neighbour rows of the positions P (n x 3, m) and radii `radius` (n, m) on the device
  // (kernels/grid.h, opencl/neighbours.cpp): q's query scale and max_neighbors, out as
  // NeighborSearch::find gives it, bit for bit. False when the device cannot (out's contents
  // are then unspecified): it lacks double precision (cl_khr_fp64), a radius is infinite, or
  // a buffer would exceed the device's largest.
  // indices_there: only the rows' number of entries comes back (out.offsets sized n + 1, its
  // last element set); the offsets and indices stay on the device (out.indices left empty)
  // until fetch_rows() brings them, and row_overlaps() and row_reach() read them there.
  // p_there: P is the positions predict() made there, which are copied, not sent.
  bool find_neighbours(const float* P, const float* radius, size_t n, const NeighborQuery& q,
                       NeighborList& out, bool indices_there = false, bool p_there = false);
  // the rows the last find_neighbours() left there into out (out.offsets sized as it gave them)
  void fetch_rows(NeighborList& out);
  // A rebuild within run() (JacobiSolve::rebuild), after a find_neighbours() whose rows
  // (`entries` entries) stay there: what the passes summed for each pair (acc.pair) and, with
  // `slips`, g.pair_slip follow each neighbour from the rows the passes read into the new rows
  // (gr_carry_pair_row), there.
  void carry_pairs(size_t n, size_t entries, bool slips);

  // The Jacobi path's contact history between grains kept on the device (kernels/history.h,
  // opencl/history.cpp), where the rows its search found are (size.rows_there). save: each row
  // entry's slip at the substep's end (gr_save_pair_slips) from p (3 n floats: sent, or taken
  // there where p_there says it is what the last run() ended with, unchanged since), g's start
  // positions, rows and carried slips and the pair sums `pair_normal` (each where the substep's
  // calls left it, else sent), kept there with the rows. load: the next substep's carried slips
  // (g.pair_slip) made there: `kept`, its rows are those saved and the slips are the saved
  // ones; else looked up by id (gr_load_pair_slips) in the saved rows, `id` the grains' ids (n;
  // null: their indices), `hist_id` the saved grains' (hist_n; null: no lookup, every slip 0),
  // ids below `table_size`. Both false where the device cannot (no such rows there, no save);
  // nothing is changed then.
  bool save_pair_history(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                         const float* p, const gr_uint* pair_normal, bool p_there = false);
  // The collider planes' slips saved at the substep's end (gr_save_plane_slips) into out (3
  // floats an entry of the planes' rows, brought back), from the positions the last run() ended
  // with and the planes, their carried slips and the summed normal corrections as it left them
  // there (collider_normal: the host's copy of those, sent only if the device holds others).
  // False where the device holds no run() of n grains since its arrays were last sent (the
  // positions save_pair_history() sent stand for its end). out null: the slips stay there, with
  // the rows, colliders and sums they belong to, for load_plane_history() (or
  // fetch_plane_history()); false where the planes there are not the last find_planes()'s.
  bool save_plane_history(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                          const float* collider_normal, float* out);
  // `same`: the grains are the saved ones in the same order (each its own index there; id and
  // hist_id not read)
  bool load_pair_history(const IterationSizes& size, bool kept, bool same, const int* id,
                         const int* hist_id, size_t hist_n, size_t table_size);
  // The next substep's carried plane slips (g.plane_slip) made there from the slips the last
  // save_plane_history() kept (gr_load_plane_slips): each grain found by id, or `same`, as
  // load_pair_history() finds it, in the planes the last find_planes() left there
  // (size.planes_there). False, nothing changed, where the device holds no such save or planes.
  bool load_plane_history(const IterationSizes& size, bool same, const int* id, const int* hist_id,
                          size_t hist_n, size_t table_size);
  // the kept plane history into host memory: its rows (n + 1), and an entry's collider, summed
  // normal correction and slip (3 floats)
  void fetch_plane_history(std::vector<uint32_t>* offsets, std::vector<int32_t>* which,
                           std::vector<float>* normal, std::vector<float>* slip);
  // the carried plane slips there (3 floats an entry) and the collider sums the last run() left
  void fetch_plane_slips(float* out, float* collider_normal, size_t entries);
  // the last save's slips (3 floats an entry) and, into *rows where given, the rows they belong
  // to; and the slips the last load made (3 floats an entry of the substep's rows), into host
  // memory
  void fetch_pair_history(float* out, NeighborList* rows = nullptr);
  void fetch_pair_slips(float* out, size_t entries);
  // the pair sums the last run() left there (`entries` of them) into host memory
  void fetch_pair_sums(gr_uint* out, size_t entries);
  // What the host reads along those rows (kernels/row_stats.h), computed where they are in runs
  // of grains and combined in run order. row_overlaps: the overlap statistics of the positions
  // P (n x 3, m, uploaded) with the radii `radius` (n, the grains' radii, uploaded once a
  // substep as gr_grains' are, begin_substep; null: the radii the search took). row_reach: the smallest reach of the rows holding `full` candidates or more, of the
  // positions the search took and the radii `radius` (as above), r_max the largest radius;
  // +infinity when none is full. Both false when the device holds no rows of n grains.
  struct RowOverlaps {
    double contacts = 0;
    float largest = 0;
    double sum = 0;
  };
  // written_there: the device holds P as the last substep's end there wrote it (SubstepEnd),
  // but for the grains this lists, which go up alone (all of P goes up when the
  // device holds no such positions of n grains).
  bool row_overlaps(const float* P, const float* radius, size_t n, RowOverlaps* out,
                    const std::vector<gr_uint>* written_there = nullptr);
  bool row_reach(const float* radius, size_t n, gr_uint full, float r_max, float* reach);
  // the longest of those rows' number of entries (gr_row_longest) into *longest; false when the
  // device holds no rows of n grains
  bool row_longest(size_t n, size_t* longest);
  // whether the device holds predicted positions of n grains (the last predict(), or a search
  // of rows or planes that took them), which calls given p_there take there
  bool holds_prediction(size_t n) const;
  // The Verlet test of those rows (gr_rows_moved): into *moved2 the largest squared distance
  // a grain has moved from the positions the last search took to those predict() made this
  // substep. False when that search took no positions of n grains or there is no such
  // prediction.
  bool rows_moved(size_t n, float* moved2);
  // the positions the last search took (n x 3) into out
  void fetch_rows_p(float* out, size_t n);
  // The grains node's sleeping test's reads along those rows: each grain's word (gr_row_sleep)
  // into out (n) at the world positions P (n x 3, uploaded; null: those the last row_overlaps()
  // took) with the radii `radius` (n, as row_overlaps takes them) and a byte a grain, `fast`;
  // written_there as row_overlaps'. False when the device holds no rows of n grains.
  bool sleep_rows(const float* P, const float* radius, const uint8_t* fast, size_t n, uint32_t* out,
                  const std::vector<gr_uint>* written_there = nullptr);

  // the positions the last run() ended with (n x 3) into p and the start it read (g.P's
  // buffer: stabilize()'s where it kept it there) into start (null: not wanted); false where the
  // device holds no such run of n grains (nothing written then)
  bool fetch_run(float* p, float* start, size_t n);

  // the Jacobi path's pre-stabilization (gr_stabilize) of the start positions x (3 n + 1
  // floats, in and out): pass after pass while go_on(pass, the largest move over a radius)
  // says so, at most `most` passes. `there`: x begins as g.P there and stays there, unwritten
  // (g.P's buffer takes it, named x for the calls that follow, the start as it went up kept for
  // the final collision test), and the predicted positions the device holds (holds_prediction)
  // move there by what the passes moved each grain (p + (x - g.P), as the host adds them);
  // false where it holds no prediction of n grains (nothing done then).
  bool stabilize(const gr_grains& g, const gr_params& prm, const IterationSizes& size, float* x,
                 int most, const std::function<bool(int, float)>& go_on, bool there = false);

  // contact_solver gauss_seidel's solve from its contacts on, in one call (gauss_seidel.cpp's
  // steps in its order, with one upload and one download): pre-stabilization when w.x is set,
  // the velocity it takes back when w.take_back is, the warm start when w.loaded is, then
  // `iterations` passes as run_sequential's, and the velocity update when w.finish is set.
  // p (3 n + 1 floats; not written with w.finish) and s.contacts in and out.
  void solve_sequential(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                        float* p, const SequentialContacts& s, const SequentialSolve& w,
                        int iterations);

  // contact_solver gauss_seidel's contact list built on the device from g's neighbour rows and
  // collider planes (gr_seq_build, grain by grain: the host's list, bit for bit), id and
  // plane_collider as gr_seq_build takes them (host arrays, null where absent). With `warm`
  // each contact starts with the load its key ended the device's last solve with, scaled by
  // `scale` (gr_seq_take_load), and is flagged for the warm start. Out: the contacts' count,
  // each block's first contact (block_grains grains a block, `blocks` of them, and the end)
  // and the blocks' links, a row of `words` 32-bit words a block (bit b of row a: a contact of
  // block a moves a grain of block b). False, the device's last list left as it was, when the
  // list would not fit one buffer or the links would take more than 64 MiB. rows_there: g's
  // rows are those the device's last find_neighbours() gave, which it then reads where they
  // are instead of taking g's.
  struct BuiltList {
    size_t count = 0;
    std::vector<gr_uint> block_start;
    size_t words = 0;
    std::vector<gr_uint> links;
  };
  bool build_sequential(const gr_grains& g, const gr_params& prm, const IterationSizes& size,
                        const int* id, const int* plane_collider, bool warm, float scale,
                        size_t block_grains, bool rows_there, BuiltList* out);
  // the list build_sequential built, in waves (GrainsSolver::order_waves, the host's: the same
  // order, bit for bit), colour by colour (colour_blocks, colour_start and colours as
  // SequentialContacts holds them); out: each block's first wave (blocks + 1) and each wave's
  // first contact, then the list's end
  void order_waves(const gr_uint* colour_blocks, const gr_uint* colour_start, size_t colours,
                   std::vector<gr_uint>* block_wave, std::vector<gr_uint>* wave_start);
  // the contacts the device's last solve left (s's blocks, parts as they went up or were built)
  // into s.contacts
  void fetch_contacts(const SequentialContacts& s);

  // The collider planes (kernels/planes.h) of n grains among `count` colliders (their meshes
  // those set_meshes() last took), found on the device: GrainsSolver::find_planes' rows, bit for bit. P and p (n x 3,
  // the substep's coordinates, world = those + origin), radius and inv_mass (n); p_there: p is
  // the positions the device's last find_neighbours() or predict() took or made, radius_there:
  // radius is the search's radii (neither then goes up). Out: each grain's first entry and the
  // end (n + 1), the entries (9 floats each: surface point, normal, the collider's velocity
  // there) and their colliders.
  // entries_stay: *plane is sized but not written; the entries stay on the device until
  // fetch_planes() brings them. rows_stay: so do the rows and colliders (*which sized, *offsets'
  // last element alone written: the number of entries), and *same_as_kept says whether they are
  // those keep_planes() last kept, compared there (false when none are kept for n grains). The
  // device keeps all three for the calls that follow (IterationSizes::planes_there).
  void find_planes(const gr_collider* colliders, size_t count, const float origin[3],
                   float query_scale, const float* P, const float* p, const float* radius,
                   const float* inv_mass, size_t n, bool p_there, bool radius_there,
                   bool entries_stay, bool rows_stay, std::vector<uint32_t>* offsets,
                   std::vector<float>* plane, std::vector<int32_t>* which, bool* same_as_kept);
  // what the last find_planes() found and left there into those of *plane (the entries),
  // *offsets and *which that are set (sized for them)
  void fetch_planes(std::vector<float>* plane, std::vector<uint32_t>* offsets = nullptr,
                    std::vector<int32_t>* which = nullptr);
  // the rows and colliders of the last find_planes() kept there (a device copy) for its later
  // calls to compare theirs with: those a contact list was built from
  void keep_planes();
  // A rebuild within run() (JacobiSolve::rebuild): hold_planes() before find_planes() keeps the
  // rows and colliders of the planes the passes read; carry_planes() after it moves what the
  // passes summed for each plane, by collider (gr_carry_plane_row): the collider sums
  // (acc.collider) with `sums`, g.plane_slip with `slips` and the impact data's slots
  // (acc.collider_dx) with `slots`, there.
  void hold_planes();
  void carry_planes(size_t n, bool sums, bool slips, bool slots);

  // A new substep: the calls until the next one may take a grain array (gr_grains' per-grain
  // arrays but the rows and planes, and the pins') sent by an earlier one from the same host
  // array and not send it again (the caller keeps each such array's values through the
  // substep), and the predicted positions the substep's search of rows or planes took
  // (SequentialSolve::p_there).
  void begin_substep();
  // The substep's predicted positions (gr_predict) of n grains made there, from g's start
  // positions (g.P, the substep's coordinates), velocities and masses and `force` (a row a grain,
  // or with force_uniform one row for every grain; null: none), sent once a substep (as
  // carry_start may have made them there): the host's floats, bit for bit, which the search of
  // rows or planes and the solve then take there (their p_there) instead of the host's.
  void predict(const gr_grains& g, const gr_params& prm, size_t n, const float* force,
               bool force_uniform);
  // The substep's start positions (P: host, the substep's coordinates, n x 3) and velocities (v,
  // or null) made there from what the last end there wrote (SubstepEnd): its world
  // positions less `origin` (as the host subtracts it) and its velocities, but for the grains
  // `changed` lists, whose host values differ from those and go up alone (16 bytes a grain for
  // the positions, 12 more for the velocities). From then on this substep's calls take P and v
  // as sent. With `from`, the grains are in another order, or others: grain i was grain
  // from[i] of the last end (0xffffffff: none, and in `changed`), and `from` goes up (4 bytes a
  // grain). False, with nothing done, when the last end there was not of n grains (without
  // `from`) or wrote no velocities and v is asked for.
  bool carry_start(const float* P, const float* v, size_t n, const float origin[3],
                   const std::vector<gr_uint>& changed, const std::vector<gr_uint>* from = nullptr);
  // What the last end there wrote, of n grains, measured there: the box of its positions
  // whose coordinates are all finite (lo > hi: none) and whether every position and velocity
  // is finite (7 floats a work-item come back). False, with nothing done, when that end was not
  // of n grains or wrote no velocities.
  bool end_bounds(size_t n, float lo[3], float hi[3], bool* finite);
  // Error control's motion measure (engine/motion_need.h) of what the last end there wrote, n
  // grains, with this substep's force (null: none; one row for all where force_uniform), masses
  // (the sleeping test's masses awake where `awake`, else the substep's) and radii, added into
  // *worst and *fall (16 bytes for each work-item, as end_bounds() has, come back). False, with
  // nothing done, where that end was not of n grains or wrote no velocities, or the device has
  // no double precision.
  bool motion(size_t n, bool has_force, bool force_uniform, bool awake, double step, double fps,
              double* worst, double* fall);
  // what the last end there wrote (world positions into P, velocities into v; either null),
  // brought back; false when that end was not of n grains (or wrote no velocities, v asked for)
  bool fetch_end(float* P, float* v, size_t n);
  // The grains node's sleeping test (kernels/sleep.h) on the device, around a substep whose
  // end stays there. sleep_begin(), after carry_start() and before predict(): each grain's
  // start (world: `P`, n x 3, sent; null: what the last end wrote, carry_start's source, in
  // the order carry_start sent, where it sent one, every grain found in that end) and
  // velocity kept, and a sleeper made a fixed grain in the arrays the substep reads (its mass,
  // inverse mass and velocity 0: g.mass, g.inv_mass and g.v are sent first, as predict() sends
  // them). The state (the node's attributes, n each: time, anchor x 3, accel x 3, contacts) goes
  // up where `state` is set, else the last call's stands. `can` (n, null: every grain) says
  // which grains may sleep; the force as predict() takes it. *changed: whether a grain sleeps
  // that did not in the last call's substep, or the reverse (always, where the last call was
  // not of n grains). False, with nothing done, where the device cannot (sleeps_there()).
  struct SleepState {
    const float* time = nullptr;
    const float* anchor = nullptr;
    const float* accel = nullptr;
    const int32_t* contacts = nullptr;
  };
  bool sleeps_there() const;
  bool sleep_begin(const gr_grains& g, const gr_sleep_params& sp, size_t n, const float* P,
                   const uint8_t* can, const float* force, bool force_uniform,
                   const SleepState* state, bool* changed);
  // The state the last sleep_end() left, of the grains of the last end there, carried into
  // this substep's order of n grains before sleep_begin() (which then takes no `state`):
  // through the order carry_start() sent this substep (grain i was grain from[i] of that end;
  // each must be one), or as it stands where carry_start() kept the order. Nothing crosses.
  // False, with nothing done, where the state is not of the last end's grains or the order is
  // neither.
  bool sleep_carry(size_t n);
  // sleep_end(), after the substep's end there (SubstepEnd) and before
  // end_bounds(): the sleepers put back or woken, by those of the substep's `colliders` that
  // moved (the array find_planes() sent: nothing goes up again) and along the rows the last
  // search left here (device_rows: of n grains), else along `rows` (sent; null: no rows), and
  // each grain's stay counted. False where no sleep_begin() of n grains came first or the end
  // is not there.
  bool sleep_end(const gr_sleep_params& sp, size_t n, bool device_rows, const NeighborList* rows,
                 const gr_collider* colliders = nullptr, size_t collider_count = 0);
  // the state the last sleep_end() left, into the host arrays given (n, n x 3, n x 3, n; any
  // null); false where it is not of n grains
  bool fetch_sleep(float* time, float* anchor, float* accel, int32_t* contacts, size_t n);

  // what has crossed between the host and the device since it was opened
  Traffic traffic() const;

  const std::string& device_name() const;
  // whether a block's contacts are shared among several work-items (GRAINS_OPENCL_SWEEP_ITEMS,
  // or a device that is not a CPU): the contacts must then come in waves (GrainsSettings::
  // sweep_waves)
  bool shares_blocks() const;
  // whether gauss_seidel's contact list may be built here (build_sequential), which
  // GRAINS_OPENCL_HOST_CONTACTS=1 refuses
  bool builds_contacts() const;
  // whether the device projects rigid shapes (SequentialContacts::shapes): it has double
  // precision
  bool shapes_there();
  // The colliders' meshes (null: an analytic shape), in the order of the colliders the planes,
  // the final collision test and the sleeping test take: their arrays go up when the meshes
  // differ from the last ones (each mesh once), for the queries there (engine/mesh_query.h).
  void set_meshes(const std::vector<std::shared_ptr<const MeshShape>>& meshes);
  // whether the device makes a mesh's queries: it has double precision
  bool meshes_there();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace grains::opencl
