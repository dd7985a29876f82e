// contact_solver gauss_seidel: the contacts of a substep projected one at a time (projected
// Gauss-Seidel at position level), each grain pair and collider plane with its own Coulomb cone,
// and each contact's load carried from one substep to the next (a warm start).
//
// Why (docs/heap-angle.md, "Gauss-Seidel with carried loads"): the Jacobi average delivers to a
// contact only the load its iterations carry down within one substep, so deep in a heap the
// friction bound is a fraction of the overburden and the packing creeps. A contact that keeps
// its load across substeps, as a DEM contact keeps its force, is bounded by the weight it
// carries.
//
// A contact c between grains i and j (j a plane for colliders) keeps two accumulators over the
// substep, ln (its normal correction) and lt (its tangential one), and a pass projects it onto
// Coulomb's cone between them: gr_seq_pass (kernels/sequential.h, which gives the formulas; the
// OpenCL device runs the same function).
//
// The warm start: every contact the last substep ended with a load (ln > 0) and that the search
// finds again starts with that load, scaled by (dt / dt_last)^2 (a position-level load is a force
// x dt^2), applied to the predicted positions before the first pass. A load is a force only when
// it balanced the grain's weight: one that stopped a landing grain or a rearrangement must not be
// repeated. So each grain i scales the repeated loads to balance its external step
// G_i = p_i - P_i - dt v_i (gravity and forces over the substep): with D_i the displacement they
// give it, s_i = clamp(-(D_i . G_i) / |D_i|^2, 0, 1), the factor that brings s D_i nearest -G_i,
// and a contact starts at the smaller s of its grains times its load. A grain at rest (D = -G)
// starts fully loaded, one whose loads also stopped it (D = -1.5 G) with its weight's share of
// them; a grain under no external force starts cold, as does, with all its contacts, a grain that
// the scaled loads would leave farther from balance than no load at all (|D' + G| > |G|).
// (The factor was 1 - |D + G| / |G|, which measured the balance rather than fitting it: it gave
// that grain three quarters of its weight, and two passes of a short substep did not find the
// rest; the grains of a settled box then sank a little every substep and pre-stabilization
// lifted them back, 40-64 passes a substep at 20 x 2, docs/heap-angle.md.)
//
// The list is built from the neighbour rows each substep, or kept from the last one while the
// rows are kept (no grain has moved a quarter of their skin), the collider planes are the same
// and so is every grain's mass, repulsion and friction (seq_list_kept); each contact then still
// holds the loads it ended with, which the warm start would otherwise look up by the grains'
// ids. The result is the same bit for bit; the DEM collapse kept 74% of its lists, and at 40 x 1
// settle_100k took 11% less time. With use_opencl the device builds the list and keeps it
// (below, and docs/opencl.md); the host's copy is brought from there when read here
// (sync_contacts).
//
// The passes run within blocks of kBlockGrains grains (a contact belongs to its lower index's
// block), the blocks in colours (colour_blocks): no two blocks of a colour touch the same moving
// grain, so they can be swept at once on several threads with what sweeping them one after
// another gives. Within a block the contacts run by lower index, or, for a device whose
// work-items share a block (a GPU), in waves (order_waves): no two contacts of a wave move one
// grain, so the device takes a wave's contacts at once. The blocks
// are cut by grain index, not by thread, and a colour's blocks are taken in ascending order: the
// result does not depend on the thread count. (The grains node sorts its grains in space each
// frame, so a block is a compact lump and a sweep within it keeps to memory a core holds.
// Coloured contacts instead of blocks, tried first, swept the whole box once a colour: a third
// slower on one thread for 100,000 grains.) Explicit constraints and clumping
// are one Jacobi group before each pass, rigid shape matching and pins their own groups after
// it (Gauss-Seidel across groups). The contacts come after the constraints, so that where the
// two disagree (a pair asked to collide that is bonded closer than contact) the grains do not
// overlap. Measured: with the constraints after the contacts such a pair stayed at its rest
// length, and snowball's clumped ball broke off 1,255 grains, 318 alone; now it leaves in
// clumps as the Jacobi path's does.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "nodes/grains/kernels/collider.h"
#include "nodes/grains/kernels/distance.h"
#include "nodes/grains/kernels/mass_shock.h"
#include "nodes/grains/kernels/warm.h"
#include "nodes/grains/opencl/iterations.h"
#include "nodes/grains/substep_context.h"

namespace grains {
namespace {

// pre-stabilization stops when its largest move has not fallen at all over 4 passes: grains
// wedged between sleepers repeated 0.0028 r for 50 passes; converging passes fall, if slowly
// (1% a pass in the DEM collapse; a column of 100 grains stopped at 0.5% over 4 passes bounced
// off its top) (docs/heap-angle.md, "Sleeping")
constexpr int kStallPasses = 4;
// the most pre-stabilization passes of a substep without carried loads (see there)
constexpr int kColdStabilizeIterations = 4096;
// load_of_: a kept contact's load is its own
constexpr uint32_t kLoadInPlace = 0xffffffffu;
// grains a block (colour_blocks)
constexpr uint32_t kBlockGrains = 1024;
// the fewest contacts a substep's passes share out among threads: below, a pass is a few
// microseconds, about what the threads' meeting at the end of each colour costs (and a scene
// that small is one or two blocks)
constexpr size_t kParallelContacts = 1024;

}  // namespace

void GrainsSolver::gauss_seidel(SubstepContext& c) {
  const gr_grains& g = c.g;
  const gr_params& prm = c.prm;
  const size_t n = n_;
  const int ni = static_cast<int>(n);
  // the predicted positions: the host reads them where the device does not solve (use_opencl
  // below takes them there)
  float* p = c.s.use_opencl ? p_.data() : host_p(c);
  const float* P = c.g.P;
  const float* const start = P;  // the substep's start before pre-stabilization
  const float dt = prm.dt;

  // the contacts: each grain pair once (from the lower index's row), then each grain's planes;
  // or the last substep's list, when nothing it was built from has changed (seq_list_kept)
  const bool pairs = g.nbr_offsets && prm.internal_collisions_weight > 0;
  std::vector<float>& grain = seq_grain_now_;
  grain.resize(3 * n);
#pragma omp parallel for schedule(static) num_threads(c.threads) if (n >= 4 * kBlockGrains)
  for (int i = 0; i < ni; ++i) {
    grain[3 * i] = g.inv_mass[i];
    grain[3 * i + 1] = pairs ? gr_repulsion_scale(&g, &prm, i) : 0.0f;
    grain[3 * i + 2] = gr_attr(g.friction, i);
  }
  // in waves for a device whose work-items share a block (order_waves)
  const bool waves = c.s.sweep_waves || (c.s.use_opencl && open_device().shares_blocks());
  const bool kept = seq_waves_ == waves && seq_list_kept(c, pairs, grain);
  // with use_opencl, a kept list that the device's last call left there stays: the device keeps
  // its loads (gr_k_keep), and the host's copy is left as is
  const bool device = c.s.use_opencl;
  const bool resident = device && kept && device_.holds_contacts;
  const bool warm = (device_.stale ? device_.loaded > 0 : !seq_loads_.empty()) && seq_dt_ > 0.0f;
  const float scale = warm ? (dt / seq_dt_) * (dt / seq_dt_) : 0.0f;
  // With use_opencl the device builds a new list from its rows and the planes it is sent, and
  // finds each contact's carried load in the list its last solve left (build_sequential: the
  // list this host would build, bit for bit), so that the list crosses neither way; a device
  // whose work-items share a block orders its waves there too (Iterations::order_waves). The
  // host builds it where the device does not: with impact data made here (which read it after
  // the passes) or rigid shapes projected here (between them), loads the device does not hold (read
  // back from a saved state), a list larger than a device buffer.
  opencl::Iterations::BuiltList built;
  const bool built_there =
      device && !kept && !c.impacts_here && !c.shapes_here && (!warm || device_.holds_contacts) &&
      open_device().builds_contacts() &&
      open_device().build_sequential(g, prm, device_sizes(c), c.d.id,
                                     g.plane_offsets ? plane_collider_.data() : nullptr, warm,
                                     scale, kBlockGrains, rows_on_device_, &built);
  if (!built_there && !resident) sync_contacts();  // the host's list and loads are read below
  if (!built_there && !kept && device_.rows_stale) {  // and the rows, which the device kept
    sync_rows();
    c.g.nbr_indices = neighbors_.indices.data();
  }
  std::vector<uint32_t>& load_of = load_of_;
  if (kept) {
    ++seq_lists_kept_;
    // each contact still holds the loads it ended the last substep with, which are what the
    // warm start would find for it by its key: those it would not find (no normal load) start
    // cold now, the others with them scaled (gr_seq_keep)
    if (warm && !resident) load_of.resize(seq_.size());
    const long lm = resident ? 0 : static_cast<long>(seq_.size());
#pragma omp parallel for schedule(static) num_threads(c.threads) if (lm >= long(kParallelContacts))
    for (long k = 0; k < lm; ++k) {
      const bool carries = gr_seq_keep(&seq_[k], warm, scale);
      if (warm) load_of[k] = carries ? kLoadInPlace : 0u;
    }
  } else {
    if (built_there) {
      // the blocks' starts and links came back: the colours and the blocks' single waves are
      // made here as for the host's list
      ++seq_lists_device_;
      seq_count_ = built.count;
      block_start_.swap(built.block_start);
      block_links_.clear();
      const size_t blocks = block_start_.size() - 1;
      for (size_t a = 0; a < blocks; ++a)
        for (size_t w = 0; w < built.words; ++w)
          for (uint32_t bits = built.links[a * built.words + w]; bits; bits &= bits - 1)
            block_links_.push_back((uint64_t(a) << 32) | (32 * w + __builtin_ctz(bits)));
      colour_linked_blocks();
      if (waves) {
        open_device().order_waves(colour_blocks_.data(), colour_start_.data(),
                                  colour_start_.size() - 1, &block_wave_, &wave_start_);
        seq_waves_ = true;
      } else {
        order_waves(c.threads, false);
      }
    } else {
      seq_.clear();
      // room for every candidate before the list is built: growing it by doubling while it is
      // built holds the old list and the new at once (56 bytes a contact, about nine a grain in a
      // settled box: 0.5 GB a million grains)
      {
        size_t most = 0;
        if (pairs)
          for (int i = 0; i < ni; ++i)
            for (gr_uint e = g.nbr_offsets[i]; e < g.nbr_offsets[i + 1]; ++e)
              most += int(g.nbr_indices[e]) > i;
        if (g.plane_offsets) most += g.plane_offsets[n];
        if (seq_.capacity() < most) {
          seq_ = std::vector<SeqContact>();  // freed before the larger list is taken
          seq_.reserve(most + most / 16);
        }
      }
      // grain by grain (gr_seq_build, which a device's build calls too), through a scratch row
      sync_planes();  // the entries (and rows, colliders) the device's planes left there
      const int* ids = c.d.id;
      const int* collider_of = plane_collider_.data();
      c.g.plane = plane_.data();
      for (int i = 0; i < ni; ++i) {
        const size_t row = (pairs ? g.nbr_offsets[i + 1] - g.nbr_offsets[i] : 0) +
                           (g.plane_offsets ? g.plane_offsets[i + 1] - g.plane_offsets[i] : 0);
        if (seq_row_.size() < row) seq_row_.resize(row);
        const gr_uint count = gr_seq_build(&g, &prm, ids, collider_of, i, seq_row_.data());
        seq_.insert(seq_.end(), seq_row_.begin(), seq_row_.begin() + count);
      }
      seq_count_ = seq_.size();
      colour_blocks();
      order_waves(c.threads, waves);
    }
    seq_grain_.swap(grain);
    // the planes it was built from: kept on the device where they stayed there (which compares
    // the next substep's with them there), else here
    seq_planes_there_ = plane_rows_there_;
    if (seq_planes_there_) {
      open_device().keep_planes();
      seq_plane_offsets_.clear();
      seq_plane_collider_.clear();
    } else {
      seq_plane_offsets_.assign(g.plane_offsets,
                                g.plane_offsets ? g.plane_offsets + n + 1 : g.plane_offsets);
      seq_plane_collider_.assign(plane_collider_.begin(), plane_collider_.end());
    }
    seq_friction_[0] = prm.friction_with_particles;
    seq_friction_[1] = prm.friction_with_colliders;
    seq_valid_ = true;
  }

  // body(q) over every contact, colour by colour, block by block, a colour's blocks shared out
  // among the threads when there are enough contacts; returns the largest body returned
  const bool parallel = c.threads > 1 && seq_.size() >= kParallelContacts;
  auto sweep = [&](auto&& body) -> float {
    // one block's run of contacts, in a loop of its own so that body is inlined into it
    auto run = [&](uint32_t b) {
      float most = 0.0f;
      SeqContact* q = seq_.data();
      for (uint32_t k = block_start_[b], e = block_start_[b + 1]; k < e; ++k)
        most = std::max(most, body(q[k]));
      return most;
    };
    float most = 0.0f;
    if (!parallel) {
      for (const uint32_t b : colour_blocks_) most = std::max(most, run(b));
      return most;
    }
    const long colours = static_cast<long>(colour_start_.size()) - 1;
#pragma omp parallel num_threads(c.threads) reduction(max : most)
    for (long col = 0; col < colours; ++col) {
#pragma omp for schedule(dynamic, 1)
      for (long t = colour_start_[col]; t < static_cast<long>(colour_start_[col + 1]); ++t)
        most = std::max(most, run(colour_blocks_[t]));
    }
    return most;
  };

  // each contact's carried load (the warm start's), found once: seq_loads_ index + 1, 0 for none;
  // with a kept list the contact holds its own (kLoadInPlace, above). The load, scaled by
  // (dt / dt_last)^2, waits in the contact's accumulators for the warm start (pre-stabilization
  // does not read them), which keeps its tangential part across the contact's normal once the
  // pre-stabilized positions are known (gr_warm_open)
  if (warm && !kept && !built_there) {
    load_of.resize(seq_.size());
    const long lm = static_cast<long>(seq_.size());
#pragma omp parallel for schedule(static) num_threads(c.threads) if (parallel)
    for (long k = 0; k < lm; ++k) {
      SeqContact& q = seq_[k];
      const SeqLoad* it = find_load(q.key);
      load_of[k] = it ? static_cast<uint32_t>(it - seq_loads_.data()) + 1u : 0u;
      if (!it) continue;
      gr_seq_take_load(&q, it->ln, gr_make3(it->lt[0], it->lt[1], it->lt[2]), scale);
    }
  }

  // with use_opencl pre-stabilization, the velocity it takes back, the warm start and the passes
  // run on the device in one call, below (opencl/iterations.h: the same steps in the same order)
  opencl::SequentialSolve on_device;
  std::vector<uint8_t>& loaded = loaded_;  // a byte a contact: 1 when it carries a load
  if (device && warm && !resident && !built_there) {
    loaded.resize(seq_.size());
    for (size_t k = 0; k < seq_.size(); ++k) loaded[k] = load_of[k] != 0u;
    on_device.loaded = loaded.data();
  }
  // the largest move of the last kStallPasses passes: sweeps whose largest move no longer
  // falls over kStallPasses passes are going round in a circle, grains wedged between fixed
  // ones (sleepers) whose overlaps no placement of them removes
  float recent[kStallPasses] = {};
  // whether another pass follows one whose largest move was `moved`
  auto go_on = [&](int pass, float moved) {
    ++stabilize_passes_;
    if (!(moved > kStabilizeTolerance)) return false;
    if (pass >= kStallPasses && moved >= recent[pass % kStallPasses]) return false;
    recent[pass % kStallPasses] = moved;
    return true;
  };

  // pre-stabilization (Macklin et al. 2014 sec. 4.4), passes in the same order until no
  // contact moves its grain more than kStabilizeTolerance of its radius (at most
  // kStabilizeIterations): the overlap of the start positions, removed from start and prediction
  // alike (no velocity, no friction). Not capped by the iterations, as the Jacobi passes are: an
  // overlap left to the passes becomes a velocity overlap / dt, which grows as the substeps
  // shrink (a DEM-settled column, whose soft contacts overlap 0.4% of d, burst at 128 substeps
  // with 10 passes and ran out 1.06 L0; converged, 0.86 L0, DEM's). A substep that starts
  // without carried loads (the first of a run) removes the overlap its input came with, however
  // deep, for up to kColdStabilizeIterations passes: the DEM column's first substep still moved
  // grains 0.083 r after 64 passes and needed 542, and what the cap left became velocity
  // (overlap / dt, 2.5 m/s at 256 substeps a frame), which kept error control at 256 substeps
  // for two frames and ran the column out 0.93 L0 instead of 0.86
  if (c.s.pre_stabilization) {
    const int most_passes = warm ? kStabilizeIterations : kColdStabilizeIterations;
    // (the device starts from its own copy of P, and sums the carried moves there)
    if (device) {
      P_stable_.resize(3 * n + 1);
      P_stable_[3 * n] = 0.0f;
    } else {
      P_stable_.assign(P, P + 3 * n);
      P_stable_.push_back(0.0f);
    }
    float* x = P_stable_.data();
    // what the contacts that carried a load moved each grain (the velocity it came with, below)
    const bool made = warm && !c.s.keep_velocity;
    if (made && !device) carried_move_.assign(3 * n, 0.0f);
    float* moved_by_carried = carried_move_.data();
    if (device) {
      on_device.most = most_passes;
      on_device.go_on = go_on;
      on_device.x = x;
      if (made) {
        on_device.take_back = true;
        on_device.v = c.d.v;
        on_device.inv_last = 1.0f / seq_dt_;
      }
    } else {
      auto stabilize = [&](const SeqContact& q) -> float {
        const bool carried = made && load_of[static_cast<size_t>(&q - seq_.data())] != 0u;
        return gr_seq_stabilize(&g, x, p, carried ? moved_by_carried : nullptr, &q);
      };
      for (int pass = 0; pass < most_passes && go_on(pass, sweep(stabilize)); ++pass) {
      }
    }
    // The velocity that made the overlap. A contact that carried a load was touching when the
    // last substep ended; the overlap it has now is the part of that substep's motion its passes
    // did not stop, which a converged substep would have stopped, velocity and all. Removing the
    // overlap from start and prediction alike keeps that velocity, and with few passes a
    // packing kept sinking into its contacts at it, pre-stabilization lifting it back each
    // substep: 10,000 settled grains at 40 x 1 reported 0.07 m/s downward while moving
    // 0.005 m/s, and took 32 pre-stabilization passes a substep (docs/heap-angle.md). So each
    // grain loses the component of its velocity against m_i, what the carried contacts moved
    // it, up to |m_i| / dt_last (the speed that overlap needed); a grain is never given speed.
    // Only carried contacts: a new contact's overlap was made by emission or by a neighbour's
    // fall, and a grain of a falling stream pushed off an emitted one lost its share of the
    // common fall sideways (grains 2.4 m/s off the DEM pile's stream).
    if (made && !device) {
      float* v = c.d.v;
      const float inv_last = 1.0f / seq_dt_;
#pragma omp parallel for schedule(static) num_threads(c.threads) if (parallel)
      for (int i = 0; i < ni; ++i) gr_warm_take_back(&g, v, p, moved_by_carried, inv_last, dt, i);
    }
    c.g.P = P = x;
  }

  // the warm start (kernels/warm.h)
  if (warm && !device) {
    const size_t m = seq_.size();
    // each contact's repeated load waits in its own accumulators (q.ln, q.lt), which the
    // passes start from, until the last sweep below scales it by the contact's factor
    std::vector<float>& factor = warm_factor_;
    std::vector<float>& normal = warm_normal_;
    factor.assign(m, 0.0f);
    normal.assign(3 * m, 0.0f);
    const long lm = static_cast<long>(m);
#pragma omp parallel for schedule(static) num_threads(c.threads) if (parallel)
    for (long k = 0; k < lm; ++k)
      if (load_of[k]) factor[k] = gr_warm_open(&g, p, &seq_[k], &normal[3 * k]);
    // what the loads, each scaled by its factor, give every moving grain (D), summed in the
    // sweep's order (the same for any thread count)
    std::vector<float>& repeat = warm_repeat_;
    auto sum_repeat = [&] {
      repeat.assign(3 * n, 0.0f);
      sweep([&](const SeqContact& q) -> float {
        const size_t k = static_cast<size_t>(&q - seq_.data());
        gr_warm_repeat(&q, &normal[3 * k], factor[k], repeat.data());
        return 0.0f;
      });
    };
    sum_repeat();
    std::vector<float>& balance = warm_balance_;
    std::vector<float>& external = warm_external_;  // G_i
    balance.resize(n);
    external.resize(3 * n);
#pragma omp parallel for schedule(static) num_threads(c.threads) if (parallel)
    for (int i = 0; i < ni; ++i)
      balance[i] = gr_warm_balance(&g, p, dt, repeat.data(), i, external.data());
#pragma omp parallel for schedule(static) num_threads(c.threads) if (parallel)
    for (long k = 0; k < lm; ++k)
      if (factor[k] > 0.0f) factor[k] = gr_warm_factor(&seq_[k], balance.data());
    // The scaled loads must not throw a grain off balance by more than a cold start would or
    // a tenth of its radius, |D' + G| <= max(|G|, r / 10) (D' what they give it): a grain whose
    // contacts are scaled unequally, a light grain under a heavy one (their contact halved by
    // the heavy grain's balance) on the ground (kept whole), would be shot up by the difference,
    // 1.7 radii at 1000:1. Each such grain starts cold, all its contacts with it, until none is
    // left (a round cuts at least one). With |G| alone the cuts ran down the DEM column from
    // every grain that was moving and it slumped to H / L0 1.54; at r / 4 a 200-grain column
    // under mass-shock scaling gained energy (docs/heap-angle.md). Nor may they lift it against
    // G by more than r / 20: with the fitted factors above, which the bound before let lift a
    // grain up to r / 10 a substep, that column rose 1.2 mm above where it stood; at r / 50 the
    // settled box's grains, starting too often cold, sank again each substep.
    std::vector<uint8_t>& cold = warm_cold_;
    cold.assign(n, 0);
    for (int cut = 1; cut;) {
      cut = 0;
      sum_repeat();
#pragma omp parallel for schedule(static) num_threads(c.threads) if (parallel)
      for (int i = 0; i < ni; ++i) cold[i] = gr_warm_cold(&g, repeat.data(), external.data(), i);
#pragma omp parallel for schedule(static) num_threads(c.threads) if (parallel) reduction(| : cut)
      for (long k = 0; k < lm; ++k) {
        const SeqContact& q = seq_[k];
        if (factor[k] > 0.0f && (cold[q.i] || (q.j >= 0 && cold[q.j]))) factor[k] = 0.0f, cut = 1;
      }
    }
    sweep([&](SeqContact& q) -> float {
      const size_t k = static_cast<size_t>(&q - seq_.data());
      gr_warm_apply(p, &q, &normal[3 * k], factor[k]);
      return 0.0f;
    });
  }

  // the passes
  gr_grains others = g;  // explicit constraints and clumping, without the contacts
  others.plane_offsets = nullptr;
  gr_params others_prm = prm;
  others_prm.internal_collisions_weight = 0.0f;
  if (!(prm.clumping_weight > 0.0f)) others.nbr_offsets = nullptr;
  const bool other_groups = others.con_offsets || others.nbr_offsets;
  // over_relaxation: successive over-relaxation of the normal loads (omega > 1 pushes past the
  // contact, the next pass takes back what overshot)
  const float relax = prm.over_relaxation;
  if (device) {
    // pre-stabilization, the velocity it takes back, the warm start (on_device, set above) and
    // the passes, rigid shapes and pins on the device in one call, the same steps in the same
    // order (opencl/iterations.h); on a device without double precision the shapes stay here,
    // each pass then a call of its own and the pins following the shapes here
    opencl::SequentialContacts on = contact_sweep();
    on.resident = resident;
    on.built = built_there;
    // the list stays there unless the host reads it before the next substep (impact data made
    // here, shapes projected here, below)
    on.stay = !c.impacts_here && !c.shapes_here;
    size_t loaded_there = 0;
    on.loaded = on.stay ? &loaded_there : nullptr;
    on.keep_warm = warm;
    on.keep_scale = scale;
    on.relax = relax;
    on_device.p_there = p_on_device_;
    on.others = other_groups ? &others : nullptr;
    on.others_prm = &others_prm;
    opencl::Iterations& cl = open_device();
    opencl::IterationSizes size = device_sizes(c);
    // the contacts' kernels read no neighbour rows: only clumping's Jacobi group does
    gr_grains gd = g;
    gd.P = start;  // the device pre-stabilizes its own copy of the start
    if (!others.nbr_offsets) gd.nbr_offsets = gd.nbr_indices = nullptr, size.pair_entries = 0;
    // the shapes after each pass there too, where the device can (double precision)
    opencl::ShapeArrays shapes;
    const bool shapes_there = c.shapes_on && !c.shapes_here;
    if (shapes_there) on.shapes = shape_arrays_there(c, &shapes);
    if (!c.shapes_on || shapes_there) {
      // the substep's end there too (write_back takes what it wrote) with the impact data, unless
      // the host makes them from the passes' positions
      opencl::SubstepEnd end;
      if (!c.impacts_here && !c.s.host_finish) on_device.finish = finish_there(c, &end);
      cl.solve_sequential(gd, prm, size, p_for_device(c, p_on_device_), on, on_device,
                          c.iterations);
    } else {
      // the contacts and the grains' arrays stay on the device between the passes (only the
      // positions cross for the shapes' projections here); the contacts come back once, after
      // the last pass
      gr_grains unpinned = gd;
      unpinned.targetP = nullptr;
      opencl::SequentialContacts kept = on;
      kept.stay = true;
      kept.loaded = nullptr;
      cl.solve_sequential(unpinned, prm, size, p_for_device(c, p_on_device_), kept, on_device, 0);
      unpinned.P = g.P;  // the passes' start: pre-stabilization's, which the solve brought back
      kept.there = true;
      for (int it = 0; it < c.iterations; ++it) {
        cl.run_sequential(unpinned, prm, size, p_.data(), kept, 1);
        project_shapes(g, prm, c.threads);
        if (g.targetP) project_pins(c);
      }
      cl.fetch_contacts(on);
    }
    p = p_.data();
    if (!finished_there_) p_made_ = true;  // the solved positions came back into p_
    device_.stale = on.stay;
    device_.loaded = loaded_there;
  }
  device_.holds_contacts = device;
  for (int it = 0; it < c.iterations && !device; ++it) {
    if (other_groups) {
      const long ln = static_cast<long>(n);
      const gr_normal_sums none{nullptr, nullptr, nullptr, nullptr, nullptr};
      float* next = p_next_.data();
#pragma omp parallel for schedule(static) num_threads(c.threads)
      for (long i = 0; i < ln; ++i) {
        const int ii = static_cast<int>(i);
        gr_store3(next, ii, gr_iterate(&others, &others_prm, p, ii, &none));
      }
      p_.swap(p_next_);
      p = p_.data();
    }
    sweep([&](SeqContact& q) -> float {
      gr_seq_pass(&g, &prm, p, &q, relax);
      return 0.0f;
    });
    if (c.shapes_on) project_shapes(g, prm, c.threads);
    if (g.targetP) project_pins(c);
  }

  // impact data: what each collider plane moved its grain over the substep, its load and its
  // friction as they ended (a plane's normal holds through the substep; a contact that took
  // back all it pushed gave nothing)
  if (c.impacts_here) impact_loads(g, seq_.data(), seq_.size(), collider_dx_.data());

  // the loads the next substep starts from (on the device, with the list, when it stays there)
  if (device_.stale) {
    seq_loads_.clear();
    seq_table_.clear();
  } else {
    store_loads();
  }
  seq_dt_ = dt;
}

void GrainsSolver::store_loads() {
  seq_loads_.clear();
  {
    size_t loaded = 0;
    for (const SeqContact& q : seq_) loaded += q.ln > 0.0f;
    if (seq_loads_.capacity() < loaded) {
      seq_loads_ = std::vector<SeqLoad>();  // as seq_: no old and new list at once
      seq_loads_.reserve(loaded + loaded / 16);
    }
  }
  for (const SeqContact& q : seq_) {
    if (!(q.ln > 0.0f)) continue;
    const float sign = gr_seq_carry_sign(&q);
    seq_loads_.push_back({q.key, q.ln, {sign * q.lt[0], sign * q.lt[1], sign * q.lt[2]}});
  }
  index_loads();
}

// The solver's state is logically the device's list; bringing the host's copy up to date changes
// no result, so a const caller (save_state, a copy) may ask for it.
void GrainsSolver::sync_contacts() const {
  if (!device_.stale) return;
  GrainsSolver& self = const_cast<GrainsSolver&>(*this);
  self.seq_.resize(seq_count_);
  self.device_.device->fetch_contacts(self.contact_sweep());
  self.store_loads();
  self.device_.stale = false;
}

opencl::SequentialContacts GrainsSolver::contact_sweep() {
  opencl::SequentialContacts on;
  on.contacts = seq_.data();
  on.count = seq_count_;
  on.block_start = block_start_.data();
  on.blocks = block_start_.size() - 1;
  on.colour_blocks = colour_blocks_.data();
  on.colour_start = colour_start_.data();
  on.colours = colour_start_.size() - 1;
  on.block_wave = block_wave_.data();
  on.wave_start = wave_start_.data();
  on.waves = wave_start_.size() - 1;
  return on;
}

// Whether the last substep's contact list serves this one unchanged: it was built from the same
// neighbour rows (the rows were kept, keep_rows), the same collider plane rows, and for every
// grain the same inverse mass (a sleeper's is 0 for its substep), repulsion scale and friction
// (grain: this substep's, 3 a grain), under the same friction scales. Height-scaled mass-shock
// shares follow the positions: that list is built anew each substep.
bool GrainsSolver::seq_list_kept(const SubstepContext& c, bool pairs,
                                 const std::vector<float>& grain) const {
  const gr_grains& g = c.g;
  if (!seq_valid_ || !c.same_rows || !pairs || c.prm.mass_shock == 2) return false;
  // the sleepers of the device's sleeping test, whose inverse masses the host does not see
  if (sleep_there_ != slept_there_ || sleep_changed_) return false;
  if (seq_friction_[0] != c.prm.friction_with_particles ||
      seq_friction_[1] != c.prm.friction_with_colliders)
    return false;
  if (plane_rows_there_ || seq_planes_there_) {
    // compared on the device, where both stayed (find_planes' rows_stay, keep_planes)
    if (!(plane_rows_there_ && seq_planes_there_ && planes_same_)) return false;
  } else {
    if (!g.plane_offsets ? !seq_plane_offsets_.empty()
                         : !std::equal(g.plane_offsets, g.plane_offsets + n_ + 1,
                                       seq_plane_offsets_.begin(), seq_plane_offsets_.end()))
      return false;
    if (g.plane_offsets && plane_collider_ != seq_plane_collider_) return false;
  }
  // bit for bit (-0 and 0 differ, as a NaN equals itself: the list is what it was built from)
  return grain.size() == seq_grain_.size() &&
         std::memcmp(grain.data(), seq_grain_.data(), grain.size() * sizeof(float)) == 0;
}

// Blocks and their colours. seq_ runs by its contacts' lower index, so block b (grains
// [b kBlockGrains, (b + 1) kBlockGrains)) owns a run of it. A contact whose other grain moves
// and lies in another block links the two blocks: both sweeps would write that grain. Two
// blocks linked to a third may both write one of its grains, so no two blocks within two links
// share a colour (greedy, in block order: each takes the first colour none of them has).
void GrainsSolver::colour_blocks() {
  const uint32_t blocks = static_cast<uint32_t>((n_ + kBlockGrains - 1) / kBlockGrains);
  block_start_.assign(size_t(blocks) + 1, 0u);
  block_links_.clear();
  // a pair's j is above its i, so bj >= bi; the contacts come by bi, so a link already made
  // from bi to bj is the one stamped bi + 1 on bj
  block_linked_.assign(blocks, 0u);
  for (const SeqContact& q : seq_) {
    const uint32_t bi = static_cast<uint32_t>(q.i) / kBlockGrains;
    ++block_start_[bi + 1];
    if (!(q.moves & 2u)) continue;
    const uint32_t bj = static_cast<uint32_t>(q.j) / kBlockGrains;
    if (bi == bj || block_linked_[bj] == bi + 1) continue;
    block_linked_[bj] = bi + 1;
    block_links_.push_back((uint64_t(bi) << 32) | bj);
  }
  for (uint32_t b = 0; b < blocks; ++b) block_start_[b + 1] += block_start_[b];
  colour_linked_blocks();
}

// The colours of block_start_'s blocks from their links (block_links_, lower << 32 | higher,
// each once, in any order: a block takes the first colour none within two links has)
void GrainsSolver::colour_linked_blocks() {
  const uint32_t blocks = static_cast<uint32_t>(block_start_.size() - 1);
  // the links both ways, by block
  block_link_start_.assign(size_t(blocks) + 1, 0u);
  for (const uint64_t l : block_links_) {
    ++block_link_start_[(l >> 32) + 1];
    ++block_link_start_[(l & 0xffffffffu) + 1];
  }
  for (uint32_t b = 0; b < blocks; ++b) block_link_start_[b + 1] += block_link_start_[b];
  block_link_to_.resize(2 * block_links_.size());
  {
    std::vector<uint32_t> at(block_link_start_.begin(), block_link_start_.end() - 1);
    for (const uint64_t l : block_links_) {
      const uint32_t lo = static_cast<uint32_t>(l >> 32), hi = static_cast<uint32_t>(l);
      block_link_to_[at[lo]++] = hi;
      block_link_to_[at[hi]++] = lo;
    }
  }
  block_colour_.assign(blocks, -1);
  std::vector<uint8_t> taken;
  int colours = 0;
  for (uint32_t b = 0; b < blocks; ++b) {
    taken.assign(size_t(colours) + 1, 0);
    for (uint32_t e = block_link_start_[b]; e < block_link_start_[b + 1]; ++e) {
      const uint32_t a = block_link_to_[e];
      if (block_colour_[a] >= 0) taken[block_colour_[a]] = 1;
      for (uint32_t f = block_link_start_[a]; f < block_link_start_[a + 1]; ++f) {
        const uint32_t z = block_link_to_[f];
        if (z != b && block_colour_[z] >= 0) taken[block_colour_[z]] = 1;
      }
    }
    int col = 0;
    while (taken[col]) ++col;
    block_colour_[b] = col;
    colours = std::max(colours, col + 1);
  }
  colour_start_.assign(size_t(colours) + 1, 0u);
  for (uint32_t b = 0; b < blocks; ++b) ++colour_start_[block_colour_[b] + 1];
  for (int col = 0; col < colours; ++col) colour_start_[col + 1] += colour_start_[col];
  colour_blocks_.resize(blocks);
  std::vector<uint32_t> at(colour_start_.begin(), colour_start_.end() - 1);
  for (uint32_t b = 0; b < blocks; ++b) colour_blocks_[at[block_colour_[b]]++] = b;
}

// Waves (`waves`: GrainsSettings::sweep_waves, or a device whose work-items share a block).
// Each block's contacts are put in runs that share no moving grain, the runs one after another:
// each contact, in the order the list was built (by lower index), joins the first wave none of
// its moving grains is in yet, and the block's contacts are stably sorted by wave. A wave's
// contacts write disjoint grains (a fixed one is only read), so a device may project them all
// at once and give, bit for bit, what projecting them one after another gives
// (opencl/iterations.h); with `waves` the CPU sweeps the same order. By lower index a block's
// sweep is one chain: a grain's first contact waits for the last one that moved the grain, so
// settle_100k's blocks of 6,500 contacts take 1,250-1,650 steps of about 4 contacts; in waves,
// 18-20 steps of 300-430 (the DEM collapse, settle_100k). Without `waves` a block is one wave,
// swept by one work-item.
// The CPU keeps the order by lower index, since a pass in waves resolves less: settle_10k at
// 20 x 2 (error control off, one thread) rested with a mean overlap of 1.66e-4 m against
// 1.14e-4 and 2-13 mJ of kinetic energy against 0.2-3.6 mJ (waves taken cyclically after the
// last wave of a contact's grains, to carry a correction further in a pass: 1.85-1.93e-4 m). At
// the defaults the two are alike: settle_10k 15.6 s against 15.9 s; the DEM collapse runs out
// 0.796 L0 against 0.863 (DEM 0.863), H/L0 1.984 against 1.986; the DEM pile stands at 56.5
// degrees against 54.7 (DEM 55.4); but keyframed_grains' skin sagged past its test (95% within
// 4.08 cm, 3.84 before) and the silo's 8 d halves came 24% apart (the test allows 20%).
// Blocks of a colour share no moving grain, so they are ordered at once on several threads
// with one set of marks.
void GrainsSolver::order_waves(int threads, bool waves) {
  const size_t blocks = block_start_.size() - 1;
  seq_waves_ = waves;
  if (!waves) {
    // by lower index: a block is one wave, which one work-item sweeps in order
    block_wave_.assign(blocks + 1, 0u);
    wave_start_.clear();
    for (size_t b = 0; b < blocks; ++b) {
      const bool any = block_start_[b + 1] > block_start_[b];
      block_wave_[b + 1] = block_wave_[b] + (any ? 1u : 0u);
      if (any) wave_start_.push_back(block_start_[b]);
    }
    wave_start_.push_back(static_cast<uint32_t>(seq_count_));
    return;
  }
  size_t largest = 0;
  for (size_t b = 0; b < blocks; ++b)
    largest = std::max<size_t>(largest, block_start_[b + 1] - block_start_[b]);
  wave_marks_.assign(2 * n_, 0u);  // per grain, the waves 0-127 it is in, one bit each
  block_waves_.resize(blocks);     // each block's waves' starts, relative to the block's
  wave_block_.resize(largest * size_t(std::max(threads, 1)));
  wave_of_.resize(largest * size_t(std::max(threads, 1)));
  const long colours = static_cast<long>(colour_start_.size()) - 1;
  for (long col = 0; col < colours; ++col) {
    const long first = colour_start_[col], last = colour_start_[col + 1];
#pragma omp parallel for schedule(dynamic, 1) \
    num_threads(threads) if (seq_.size() >= kParallelContacts)
    for (long t = first; t < last; ++t) {
      const uint32_t b = colour_blocks_[t];
      const size_t s = block_start_[b], e = block_start_[b + 1];
      gr_ulong* mark = wave_marks_.data();
      uint32_t* wave = wave_of_.data() + largest * size_t(omp_get_thread_num());
      SeqContact* copy = wave_block_.data() + largest * size_t(omp_get_thread_num());
      // beyond 128 waves (a grain touching more than a hundred others) a contact has a wave of
      // its own: no mark needed
      uint32_t count = 128, most = 0;
      for (size_t k = s; k < e; ++k) {
        const uint32_t w = gr_seq_wave(mark, &seq_[k], &count);
        wave[k - s] = w;
        most = std::max(most, w + 1);
      }
      // the block's waves' starts (none empty below 128: a contact takes the first free wave)
      std::vector<uint32_t>& at = block_waves_[b];
      at.assign(size_t(most) + 1, 0u);
      for (size_t k = s; k < e; ++k) ++at[wave[k - s] + 1];
      for (uint32_t w = 0; w < most; ++w) at[w + 1] += at[w];
      std::copy(seq_.begin() + s, seq_.begin() + e, copy);
      for (size_t k = s; k < e; ++k) seq_[s + at[wave[k - s]]++] = copy[k - s];
      // at[w] is now where wave w ends: the starts, without the empty waves (above 128 the
      // numbers not taken)
      at.insert(at.begin(), 0u);
      at.pop_back();
      at.erase(std::unique(at.begin(), at.end()), at.end());
      for (size_t k = s; k < e; ++k) {
        const SeqContact& q = seq_[k];
        if (q.moves & 1u) mark[2 * size_t(q.i)] = mark[2 * size_t(q.i) + 1] = 0;
        if (q.moves & 2u) mark[2 * size_t(q.j)] = mark[2 * size_t(q.j) + 1] = 0;
      }
    }
  }
  // the waves' starts, block by block
  block_wave_.assign(blocks + 1, 0u);
  for (size_t b = 0; b < blocks; ++b)
    block_wave_[b + 1] = block_wave_[b] + static_cast<uint32_t>(block_waves_[b].size() - 1);
  wave_start_.resize(size_t(block_wave_[blocks]) + 1);
  for (size_t b = 0; b < blocks; ++b)
    for (uint32_t w = block_wave_[b]; w < block_wave_[b + 1]; ++w)
      wave_start_[w] = block_start_[b] + block_waves_[b][w - block_wave_[b]];
  wave_start_.back() = static_cast<uint32_t>(seq_.size());
}

void GrainsSolver::index_loads() {
  int bits = 4;
  while ((size_t(1) << bits) < 2 * seq_loads_.size()) ++bits;
  seq_table_.assign(size_t(1) << bits, 0u);
  seq_table_bits_ = bits;
  const size_t mask = seq_table_.size() - 1;
  for (size_t k = 0; k < seq_loads_.size(); ++k) {
    size_t h = gr_seq_slot(seq_loads_[k].key, bits);
    while (seq_table_[h]) h = (h + 1) & mask;
    seq_table_[h] = static_cast<uint32_t>(k + 1);
  }
}

const GrainsSolver::SeqLoad* GrainsSolver::find_load(uint64_t key) const {
  if (seq_table_.empty()) return nullptr;
  const size_t mask = seq_table_.size() - 1;
  for (size_t h = gr_seq_slot(key, seq_table_bits_); seq_table_[h]; h = (h + 1) & mask) {
    const SeqLoad& l = seq_loads_[seq_table_[h] - 1];
    if (l.key == key) return &l;
  }
  return nullptr;
}

}  // namespace grains
