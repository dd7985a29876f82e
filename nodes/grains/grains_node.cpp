// grains: the POP Grains node. Gathers the points of its stream (and group) into compact arrays,
// runs one PBD substep (solver.h) and scatters P and v back, marking the points ispbd = 1 so the
// solver leaves them alone. Parameter names are the help page's labels in snake_case.
//
// Impact data (add_impact_data), per point, for the frame (reset at its first substep):
//   impact         int   1 when the grain touched a collider during the frame
//   impactimpulse  float N s, the summed normal impulse the colliders gave it over the frame's
//                  substeps: m x (its velocity change due to the collider) . n
//   impactP        vec   m, the contact point of the strongest substep contact
//   impactN        vec   unit, that contact's normal (out of the collider)
//   impactother    int   that contact's collider index (the solver's `colliders` order);
//                  grain-grain contacts are not recorded (reserved: -1 - id of the other grain)
// Collision feedback (enable_collision_feedback): each collider receives the opposite of the
// momentum it gave the grains, and the angular impulse (x_contact - collider translate) x that,
// accumulated over the frame (engine ColliderFeedback -> DIR/colliders.csv).
#include "nodes/grains/grains_node.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <unordered_map>

#include "engine/node.h"
#include "nodes/grains/kernels/row_stats.h"
#include "nodes/grains/opencl/device.h"
#include "nodes/grains/sleep_rows.h"
#include "nodes/grains/solver.h"
#include "nodes/register.h"

namespace grains {
namespace {

class GrainsNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    const GrainsSettings st = settings(ctx.params, ctx);
    if (st.activation <= 0) return;
    ParticleStore& s = ctx.pts;
    const std::string& group = st.group;
    const int32_t* g = group.empty() ? nullptr : s.i_if(group_attribute(group));
    if (!group.empty() && !g) return;  // the group does not exist yet: no member
    idx_.clear();
    for (uint32_t k : ctx.members)
      if (!g || g[k]) idx_.push_back(k);
    size_t n = idx_.size();
    if (n == 0) return;

    float half_sep = st.particle_separation * 0.5f;
    // the solver's order: cell order at the start of each frame, or whenever the grains
    // (their ids, in store order) change; between, the same order, so that the solver may keep
    // its neighbour rows from one substep to the next
    const int32_t* id = s.i_if("id");
    members_key_.resize(n);
    for (size_t k = 0; k < n; ++k) members_key_[k] = id ? id[idx_[k]] : static_cast<int32_t>(idx_[k]);
    const bool resorted =
        ctx.time.substep == 0 || members_key_ != sorted_key_ || sorted_.size() != n;
    if (resorted) {
      sort_by_cell(s, st, half_sep);
      sorted_ = idx_;
      sorted_key_ = members_key_;
    } else {
      idx_ = sorted_;
    }
    // the sleeping test, a global mass shock and constraints read the grains' positions here
    // every substep; else the substep's end may stay on the device (use_opencl,
    // GrainsData::may_hold_end), held in the store (hold_end). Impact data and collision
    // feedback read only the impact arrays, which the device makes where it holds its end
    // (GrainsSolver::finish_there: the host's final collision test or impact data end it here)
    const bool impacts = st.add_impact_data, feedback = st.enable_collision_feedback;
    const bool sleeping = st.sleep_speed > 0 && !impacts && !feedback;
    // with use_opencl the device makes the whole sleeping test where it can
    // (GrainsSolver::sleeps_on_device), which then reads no position here
    const bool sleep_there =
        sleeping && st.use_opencl && s.prim_count() == 0 &&
        solver_.sleeps_on_device(st, ctx.colliders.data(), ctx.colliders.size());
    const bool may_hold = st.use_opencl && (!sleeping || sleep_there) &&
                          st.mass_shock() != MassShock::Global && s.prim_count() == 0;
    // where this node's last substep left its end held and nothing has read its positions
    // since (nor changed its velocities), the substep starts from there: the same grains in
    // the same order, the velocities either still held or brought back unchanged
    bool start_held = false;
    if (may_hold && !resorted && s.held_by("P", this) && solver_.end_held()) {
      start_held = s.held_by("v", this);
      if (!start_held) {
        gather3(s.v3("v"), v_);
        start_held = std::memcmp(v_.data(), solver_.end_velocities(), 3 * n * sizeof(float)) == 0;
      }
    }
    if (start_held) {
      s.claim("P", this);
      s.claim("v", this);
      P_.resize(3 * n);  // written by the substep, not read
      v_.resize(3 * n);
    } else {
      gather3(s.v3("P"), P_);  // a hold of this node's is fetched first
      gather3(s.v3("v"), v_);
    }
    gather1(s.f("mass"), mass_);
    gather1(s.f("pscale"), r_);
    for (float& r : r_)
      if (!(r > 0)) r = half_sep;  // no pscale: the separation hint gives the radius
    GrainsData d;
    d.n = n;
    d.P = P_.data();
    d.v = v_.data();
    d.force = s.v3("force");  // read in place through idx_: a copy would cost 12 B a grain
    d.force_index = idx_.data();
    d.mass = mass_.data();
    d.pscale = r_.data();
    d.friction = optional(s, "friction", friction_);
    d.repulsionweight = optional(s, "repulsionweight", rw_);
    d.repulsionstiffness = optional(s, "repulsionstiffness", rs_);
    d.attractionweight = optional(s, "attractionweight", aw_);
    d.attractionstiffness = optional(s, "attractionstiffness", as_);
    if (st.mass_shock() == MassShock::Global) {
      shock_.assign(n, 1.0f);
      d.shockmass = shock_.data();
    }
    // explicit constraints, and rigid shape matching's connectivity: the gathered primitives
    if (st.explicit_constraints_weight > 0 || st.enable_rigid_shape_matching) gather_constraints(s, d);
    // ids: rigid shape matching's rest shapes and the solver's contact history follow them
    ids_.resize(n);
    for (size_t k = 0; k < n; ++k) ids_[k] = id ? id[idx_[k]] : static_cast<int32_t>(idx_[k]);
    d.id = ids_.data();
    // pins: only with a targetstiffness attribute (missing = no pin) and nonzero parameters
    if (st.target_weight > 0 && st.target_stiffness > 0 && s.f_if("targetstiffness")) {
      d.targetstiffness = optional(s, "targetstiffness", ts_);
      d.targetweight = optional(s, "targetweight", tw_);
      if (const float* tp = s.v3_if("targetP"))
        gather3(tp, tp_);
      else
        tp_.assign(3 * n, 0.0f);  // the attribute's default: the origin
      d.targetP = tp_.data();
    }
    const size_t K = GrainsSolver::kContactSlots;
    if ((impacts || feedback) && !ctx.colliders.empty()) {
      imp_j_.assign(3 * K * n, 0.0f);
      imp_x_.assign(3 * K * n, 0.0f);
      imp_n_.assign(3 * K * n, 0.0f);
      imp_c_.assign(K * n, -1);
      d.impact_impulse = imp_j_.data();
      d.impact_point = imp_x_.data();
      d.impact_normal = imp_n_.data();
      d.impact_collider = imp_c_.data();
    }
    // a sleeper exchanges no impulse with the colliders: impact data and collision feedback
    // keep every grain awake, so that a resting heap still presses on what holds it
    if (sleep_there)
      sleep_on_device(s, d, st, resorted);
    else if (sleeping)
      put_to_sleep(s, d, st);
    d.may_hold_end = may_hold;
    d.start_held = start_held;
    // stats only for error control: the evaluator measures each frame itself (measure_frame)
    GrainsStats stats;
    solver_.substep(d, st, ctx.colliders.data(), ctx.colliders.size(),
                    ctx.substep_error ? &stats : nullptr);
    if (sleep_there)
      hold_sleep(s);
    else if (sleeping)
      update_sleep(s, st, ctx.colliders);
    if (ctx.substep_error) *ctx.substep_error = std::max(*ctx.substep_error, stats.mean_penetration);
    if (d.prim_count > 0) scatter_constraints(s);
    if (impacts) write_impacts(ctx, d);
    if (feedback && d.impact_collider && ctx.feedback && ctx.feedback->size() == ctx.colliders.size()) {
      // serial, in grain and slot order: the same sums for any thread count
      for (size_t e = 0; e < K * n; ++e) {
        int32_t c = imp_c_[e];
        if (c < 0) continue;
        Vec3 j = load3(imp_j_.data(), e) * -1.0f;  // on the collider: the opposite
        ColliderFeedback& fb = (*ctx.feedback)[c];
        fb.impulse += j;
        fb.angular_impulse += cross(load3(imp_x_.data(), e) - ctx.colliders[c].pose.t, j);
      }
      if (ctx.feedback_on) *ctx.feedback_on = true;
    }

    int32_t* pbd = s.i("ispbd");
    for (size_t k = 0; k < n; ++k) pbd[idx_[k]] = 1;
    if (solver_.end_held()) {
      hold_end(s);
    } else {
      float* P = s.v3("P");
      float* v = s.v3("v");
      for (size_t k = 0; k < n; ++k) {
        uint32_t i = idx_[k];
        store3(P, i, load3(P_.data(), k));
        store3(v, i, load3(v_.data(), k));
      }
    }
    if (d.shockmass) {
      float* sm = s.f("shockmass");
      for (size_t k = 0; k < n; ++k) sm[idx_[k]] = shock_[k];
    }
  }

  // Error control's motion measure of the end this node holds on the device (hold_end), made
  // there (GrainsSolver::motion_on_device) where this node's grains are every grain of the store
  // and the masses, radii and forces the store holds for them are those the device read: the
  // same floats as the host's measure, whose reads would bring the velocities back (12 bytes a
  // grain) after every substep.
  bool held_motion(const ParticleStore& s, double fps, const MotionBounds& bounds, double* worst,
                   double* fall) override {
    const size_t n = held_idx_.size();
    if (!s.held_by("v", this) || !solver_.end_held() || n != mass_.size() || n != r_.size())
      return false;
    const int32_t* pbd = s.i_if("ispbd");
    const float* m = s.f_if("mass");
    const float* r = s.f_if("pscale");
    const float* F = s.v3_if("force");
    if (!pbd || !m || !r || !s.has("P")) return false;
    size_t grains = 0;
    for (size_t i = 0; i < s.size(); ++i) grains += pbd[i] != 0;
    if (grains != n) return false;
    bool uniform = false;
    const float* rows = solver_.device_forces(&uniform);
    if (!F != !rows) return false;
    for (size_t k = 0; k < n; ++k) {
      const uint32_t i = held_idx_[k];
      if (!pbd[i] || std::memcmp(&m[i], &mass_[k], sizeof(float)) != 0 ||
          std::memcmp(&r[i], &r_[k], sizeof(float)) != 0 ||
          (F && std::memcmp(F + 3 * size_t(i), rows + (uniform ? 0 : 3 * k), 3 * sizeof(float))))
        return false;
    }
    return solver_.motion_on_device(bounds.step, fps, worst, fall);
  }

  // the solver's (its cell order is made again at each frame's first substep; impact data
  // starts again with each frame)
  void save_state(StateWriter& w) const override { solver_.save_state(w); }
  void load_state(StateReader& r) override { solver_.load_state(r); }
  const GrainsSolver& solver() const { return solver_; }  // grains_solver()

 private:
  // The table's rows (kernels/param_table.h) evaluated, and the moment's substep.
  GrainsSettings settings(const ParamSet& p, const CookContext& ctx) const {
    GrainsSettings st;
#define GR_READ_FLOAT(name) static_cast<float>(p.f(#name))
#define GR_READ_INT(name) p.i(#name)
#define GR_READ_TOGGLE(name) p.b(#name)
#define GR_READ_VECTOR(name) p.v3(#name)
#define GR_READ_MENU(name) p.choice(#name)
#define GR_READ_STRING(name) p.s(#name)
#define GR_PARAM(kind, name, def, home, modifiers, meaning) st.name = GR_READ_##kind(name);
#include "nodes/grains/kernels/param_table.h"
#undef GR_PARAM
    st.dt = static_cast<float>(ctx.time.dt);
    // stiffness fractions k / (substeps x iterations) count the solver's own substeps, so a
    // stiffness means the same whatever error control adds
    st.substeps = ctx.time.base_substeps;
    st.base_dt = static_cast<float>(1.0 / (ctx.time.fps * std::max(1, ctx.time.base_substeps)));
    st.keep_velocity = ctx.time.stabilize;
    st.threads = ctx.threads;
    return st;
  }

  // Sleeping (sleep_speed > 0; DESIGN §4; kernels/sleep.h), its speeds in grain radii a second
  // (one number serves millimetre sand and metre boulders). Point attributes carry it from
  // substep to substep: sleepanchor, where the grain's current stay began, sleeptime, how long
  // (s) it has stayed within sleep_speed x sleep_time radii of it, sleepaccel, its force / mass
  // when it fell asleep, and sleepcontacts, how many grains touched it then.
  // A grain whose sleeptime has reached sleep_time sleeps: for the substep it is a fixed grain
  // (mass 0, v 0), which the others lean on and bounce off like the help page's fixed grains,
  // and it ends the substep where it began. Pinned grains and constraint endpoints never sleep
  // (a sleeper would anchor its partner). The host makes it here (put_to_sleep, update_sleep),
  // a device around its substep (sleep_on_device), with the same functions.
  static gr_sleep_params sleep_params(const GrainsSettings& st) {
    gr_sleep_params sp;
    sp.dt = st.dt;
    sp.sleep_time = st.sleep_time;
    sp.stay = st.sleep_speed * st.sleep_time;
    sp.wake = 4.0f * st.sleep_speed;
    return sp;
  }
  static constexpr const char* kSleepFloats[] = {"sleeptime", "sleepanchor", "sleepaccel"};

  // can_sleep_: 0 for a constraint's endpoint or a pinned grain (a grain without mass is
  // refused by the test itself); whether any is
  bool mark_can_sleep(const GrainsData& d) {
    const size_t n = idx_.size();
    can_sleep_.assign(n, 1);
    bool any = false;
    for (size_t c = 0; c < 2 * d.prim_count; ++c) can_sleep_[d.prim_points[c]] = 0, any = true;
    if (d.targetstiffness)
      for (size_t k = 0; k < n; ++k)
        if (d.targetstiffness[k] > 0) can_sleep_[k] = 0, any = true;
    return any;
  }

  // the state, gathered from the store
  void gather_sleep_state(ParticleStore& s) {
    gather1(s.f("sleeptime"), sleep_time_);
    gather3(s.v3("sleepanchor"), sleep_anchor_);
    gather3(s.v3("sleepaccel"), sleep_accel_);
    const int32_t* touched = s.i("sleepcontacts");
    sleep_contacts_.resize(idx_.size());
    for (size_t k = 0; k < idx_.size(); ++k) sleep_contacts_[k] = touched[idx_[k]];
  }

  // Before the substep, here: which grains sleep through it (gr_sleep_begin), made fixed grains.
  void put_to_sleep(ParticleStore& s, GrainsData& d, const GrainsSettings& st) {
    const size_t n = idx_.size();
    mark_can_sleep(d);
    awake_mass_ = mass_;
    v_start_ = v_;
    P_start_ = P_;
    gather_sleep_state(s);
    asleep_.assign(n, 0);
    woken_.assign(n, 0);
    fast_.assign(n, 0);
    sleep_ = gr_sleep{};
    sleep_.time = sleep_time_.data();
    sleep_.anchor = sleep_anchor_.data();
    sleep_.accel = sleep_accel_.data();
    sleep_.contacts = sleep_contacts_.data();
    sleep_.can = can_sleep_.data();
    sleep_.mass = awake_mass_.data();
    sleep_.radius = r_.data();
    sleep_.force = s.v3("force");
    sleep_.force_index = idx_.data();
    sleep_.start = P_start_.data();
    sleep_.start_v = v_start_.data();
    sleep_.asleep = asleep_.data();
    sleep_.woken = woken_.data();
    sleep_.fast = fast_.data();
    const gr_sleep_params sp = sleep_params(st);
    for (size_t k = 0; k < n; ++k) {
      if (!sleep_begin(sp, sleep_, k, P_start_.data())) continue;
      asleep_[k] = 1;
      mass_[k] = 0.0f;
      store3(v_.data(), k, Vec3{});
    }
  }

  // After the substep, here: the sleepers put back or woken (gr_sleep_settle), woken by a
  // collider that moved this substep and touches them at its start or end pose (a floor that
  // drops away leaves none hanging), or along their rows (gr_sleep_rows_wake), and every
  // grain's stay counted (gr_sleep_stay). Each grain writes only its own slots: the same for
  // any thread count.
  void update_sleep(ParticleStore& s, const GrainsSettings& st,
                    const std::vector<ColliderState>& colliders) {
    const size_t n = idx_.size();
    const gr_sleep_params sp = sleep_params(st);
    bool moved = false;  // a sleeper put back where it began (its substep moved it a little)
    for (size_t k = 0; k < n; ++k)
      moved = sleep_settle(sp, sleep_, k, P_.data(), v_.data()) || moved;
    // Each grain's reads along its neighbour row (kernels/row_stats.h), made where the rows are:
    // on the device while they stay there (use_opencl), else along the host's (sleep_rows.h)
    const bool there = solver_.sleep_rows_on_device(P_.data(), moved, fast_.data(), &row_words_);
    const NeighborList* rows = there ? nullptr : solver_.candidates();
    // the grains within GR_SLEEP_NEAR x (r_k + r_j) of grain k, or within GR_SLEEP_KEPT x
    // (r_k + r_j) when `kept`
    auto touching = [&](size_t k, bool kept) -> int32_t {
      if (there)
        return static_cast<int32_t>((row_words_[k] >> (kept ? 15 : 0)) & GR_SLEEP_COUNT_MAX);
      const float reach = kept ? GR_SLEEP_KEPT : GR_SLEEP_NEAR;
      return rows ? static_cast<int32_t>(sleep_row_near(*rows, P_.data(), r_.data(), k, reach)) : 0;
    };
    auto fast_near = [&](size_t k) {
      if (there) return (row_words_[k] & GR_SLEEP_FAST) != 0;
      return sleep_row_fast_near(*rows, P_.data(), r_.data(), fast_.data(), k, GR_SLEEP_NEAR);
    };
    for (const ColliderState& col : colliders) {
      if (col.still()) continue;
      const gr_collider c = to_gr(col);
      for (size_t k = 0; k < n; ++k)
        if (asleep_[k] && !woken_[k] &&
            sleep_collider_near(sp, sleep_, k, c, col.shape.mesh.get(), P_.data()))
          woken_[k] = 1;
    }
    if (there || rows) {
      for (size_t k = 0; k < n; ++k) {
        if (!asleep_[k] || woken_[k]) continue;
        const int32_t kept = touching(k, true);
        gr_sleep_rows_wake(&sleep_, static_cast<int>(k), kept,
                           kept < sleep_contacts_[k] ? 0 : fast_near(k));
      }
    }
    for (size_t k = 0; k < n; ++k)
      if (sleep_stay(sp, sleep_, k, P_.data(), v_.data())) sleep_contacts_[k] = touching(k, false);
    float* T = s.f("sleeptime");
    float* A = s.v3("sleepanchor");
    float* a_slept = s.v3("sleepaccel");
    int32_t* touched = s.i("sleepcontacts");
    for (size_t k = 0; k < n; ++k) {
      const uint32_t i = idx_[k];
      T[i] = sleep_time_[k];
      store3(A, i, load3(sleep_anchor_.data(), k));
      store3(a_slept, i, load3(sleep_accel_.data(), k));
      touched[i] = sleep_contacts_[k];
    }
  }

  // The device makes the test around the substep (GrainsData::sleep) from its state, which it
  // keeps from one substep to the next while the store's attributes stay held by this node
  // (hold_sleep) and the grains keep their order; else the state goes up from the store.
  void sleep_on_device(ParticleStore& s, GrainsData& d, const GrainsSettings& st, bool resorted) {
    const size_t n = idx_.size();
    sleep_in_ = GrainsSleep{};
    sleep_in_.params = sleep_params(st);
    if (mark_can_sleep(d)) sleep_in_.can = can_sleep_.data();
    bool there = !resorted && solver_.sleep_state_there(n) && s.held_by("sleepcontacts", this);
    for (const char* name : kSleepFloats) there = there && s.held_by(name, this);
    if (there) {
      for (const char* name : kSleepFloats) s.claim(name, this);
      s.claim("sleepcontacts", this);
    } else {
      gather_sleep_state(s);
      sleep_in_.time = sleep_time_.data();
      sleep_in_.anchor = sleep_anchor_.data();
      sleep_in_.accel = sleep_accel_.data();
      sleep_in_.contacts = sleep_contacts_.data();
    }
    d.sleep = &sleep_in_;
  }

  // the state the device's test left there, held in the store: each attribute is brought back
  // by its first read, through the grains' order of this substep (held_idx_)
  void hold_sleep(ParticleStore& s) {
    held_idx_ = idx_;
    auto scatter = [this, &s](const char* name, int width, const std::function<void(float*)>& get) {
      const size_t n = held_idx_.size();
      std::vector<float> from(width * n);
      get(from.data());
      float* to = width == 3 ? s.v3(name) : s.f(name);
      for (size_t k = 0; k < n; ++k)
        std::copy_n(&from[width * k], width, to + width * size_t(held_idx_[k]));
    };
    s.hold("sleeptime", this, [this, scatter] {
      scatter("sleeptime", 1,
              [this](float* to) { solver_.fetch_sleep_state(to, nullptr, nullptr, nullptr); });
    });
    s.hold("sleepanchor", this, [this, scatter] {
      scatter("sleepanchor", 3,
              [this](float* to) { solver_.fetch_sleep_state(nullptr, to, nullptr, nullptr); });
    });
    s.hold("sleepaccel", this, [this, scatter] {
      scatter("sleepaccel", 3,
              [this](float* to) { solver_.fetch_sleep_state(nullptr, nullptr, to, nullptr); });
    });
    s.hold("sleepcontacts", this, [this, &s] {
      std::vector<int32_t> from(held_idx_.size());
      solver_.fetch_sleep_state(nullptr, nullptr, nullptr, from.data());
      int32_t* to = s.i("sleepcontacts");
      for (size_t k = 0; k < held_idx_.size(); ++k) to[held_idx_[k]] = from[k];
    });
  }

  // The primitives whose two endpoints are both gathered grains, with compact endpoints. A
  // missing restlength is the distance now (stored, so it holds from here on).
  void gather_constraints(ParticleStore& s, GrainsData& d) {
    prims_.clear();
    pairs_.clear();
    const size_t m = s.prim_count();
    if (m == 0) return;
    compact_.assign(s.size(), -1);
    for (size_t k = 0; k < idx_.size(); ++k) compact_[idx_[k]] = static_cast<int32_t>(k);
    if (!s.prim_f_if("restlength")) {
      float* rest = s.prim_f("restlength");
      const float* P = s.v3("P");
      const std::vector<int32_t>& e = s.prim_points();
      for (size_t q = 0; q < m; ++q) rest[q] = length(load3(P, e[2 * q]) - load3(P, e[2 * q + 1]));
    }
    const std::vector<int32_t>& e = s.prim_points();
    for (size_t q = 0; q < m; ++q) {
      int32_t a = compact_[e[2 * q]], b = compact_[e[2 * q + 1]];
      if (a < 0 || b < 0) continue;
      prims_.push_back(static_cast<uint32_t>(q));
      pairs_.insert(pairs_.end(), {a, b});
    }
    const size_t mc = prims_.size();
    if (mc == 0) return;
    const float* rest = s.prim_f("restlength");
    const float* strength = s.prim_f("strength");
    const float* strain = s.prim_f("strain");
    rest_.resize(mc);
    strength_.resize(mc);
    strain_.resize(mc);
    dead_.assign(mc, 0);
    for (size_t c = 0; c < mc; ++c) {
      rest_[c] = rest[prims_[c]];
      strength_[c] = strength[prims_[c]];
      strain_[c] = strain[prims_[c]];
    }
    d.prim_count = mc;
    d.prim_points = pairs_.data();
    d.restlength = rest_.data();
    d.strength = strength_.data();
    d.strain = strain_.data();
    d.prim_dead = dead_.data();
    d.constraintweight = optional(s, "constraintweight", cw_);
    d.constraintstiffness = optional(s, "constraintstiffness", cs_);
  }

  // strain back to the primitives; broken constraints and strands removed
  void scatter_constraints(ParticleStore& s) {
    float* strain = s.prim_f("strain");
    bool any_dead = false;
    for (size_t c = 0; c < prims_.size(); ++c) {
      strain[prims_[c]] = strain_[c];
      any_dead = any_dead || dead_[c];
    }
    if (!any_dead) return;
    std::vector<uint8_t> dead(s.prim_count(), 0);
    for (size_t c = 0; c < prims_.size(); ++c) dead[prims_[c]] = dead_[c];
    s.remove_prims(dead);
  }

  // Impact attributes (see the top of the file): cleared at the frame's first substep, then the
  // normal impulse adds up and the strongest substep contact names the point, normal and other.
  void write_impacts(CookContext& ctx, const GrainsData& d) {
    ParticleStore& s = ctx.pts;
    int32_t* hit = s.i("impact");
    float* J = s.f("impactimpulse");
    float* X = s.v3("impactP");
    float* N = s.v3("impactN");
    int32_t* other = s.i("impactother");
    const int32_t* id = s.i_if("id");
    if (ctx.time.substep == 0) {
      strongest_.clear();
      for (uint32_t i : idx_) {
        hit[i] = 0;
        J[i] = 0;
        other[i] = -1;
        store3(X, i, Vec3{});
        store3(N, i, Vec3{});
      }
    }
    if (!d.impact_collider) return;
    const size_t K = GrainsSolver::kContactSlots;
    for (size_t e = 0; e < K * idx_.size(); ++e) {
      int32_t c = imp_c_[e];
      if (c < 0) continue;
      uint32_t i = idx_[e / K];
      Vec3 n = load3(imp_n_.data(), e);
      float jn = dot(load3(imp_j_.data(), e), n);
      hit[i] = 1;
      J[i] += jn;
      float& best = strongest_[id ? id[i] : static_cast<int32_t>(i)];
      if (other[i] < 0 || jn > best) {
        best = jn;
        other[i] = c;
        store3(X, i, load3(imp_x_.data(), e));
        store3(N, i, n);
      }
    }
  }

  // The substep's end held on the device (GrainsSolver::end_held): the store's P and v of this
  // node's grains are brought back by the first read of each (particles.h), through the grains'
  // order as it is now (held_idx_: the next substep may sort them again), or taken up by the
  // next substep (cook: start_held). Each is 12 bytes a grain that crosses once a frame, or not
  // at all where the frame ends with the next hold, instead of every substep.
  void hold_end(ParticleStore& s) {
    held_idx_ = idx_;
    auto scatter = [this, &s](const char* name, const float* from) {
      float* to = s.v3(name);
      for (size_t k = 0; k < held_idx_.size(); ++k) store3(to, held_idx_[k], load3(from, k));
    };
    s.hold("P", this, [this, scatter] { scatter("P", solver_.end_positions()); });
    s.hold("v", this, [this, scatter] { scatter("v", solver_.end_velocities()); });
  }

  // The solver gets its grains in cell order (z-order of cells one interaction distance wide), so
  // that grains near in space are near in memory and the iterations' neighbour reads stay in
  // cache. Only the solver's compact copy is ordered; the store keeps its order. The order
  // depends on the positions alone, so every thread count sees the same one.
  void sort_by_cell(ParticleStore& s, const GrainsSettings& st, float half_sep) {
    const size_t n = idx_.size();
    if (n < 2) return;
    const float* pscale = s.f_if("pscale");
    float r_max = 0;
    for (uint32_t i : idx_) r_max = std::max(r_max, pscale && pscale[i] > 0 ? pscale[i] : half_sep);
    gather3(s.v3("P"), P_);
    std::vector<uint32_t> order =
        cell_sort_order(P_.data(), n, 2.0f * r_max * st.neighbor_query_scale);
    for (size_t k = 0; k < n; ++k) order[k] = idx_[order[k]];
    idx_.swap(order);
  }

  void gather3(const float* a, std::vector<float>& out) const {
    out.resize(3 * idx_.size());
    for (size_t k = 0; k < idx_.size(); ++k) store3(out.data(), k, load3(a, idx_[k]));
  }
  void gather1(const float* a, std::vector<float>& out) const {
    out.resize(idx_.size());
    for (size_t k = 0; k < idx_.size(); ++k) out[k] = a[idx_[k]];
  }
  // A scaling attribute: nullptr when the points lack it (scale 1).
  const float* optional(const ParticleStore& s, const char* name, std::vector<float>& out) const {
    const float* a = s.f_if(name);
    if (!a) return nullptr;
    gather1(a, out);
    return out.data();
  }

  GrainsSolver solver_;
  std::vector<uint32_t> idx_;
  std::vector<float> P_, v_, mass_, r_, friction_, rw_, rs_, aw_, as_, shock_;
  // explicit constraints of the gathered grains: store primitive index, compact endpoints
  std::vector<int32_t> compact_, pairs_;
  std::vector<uint32_t> prims_;
  std::vector<float> rest_, strength_, strain_, cw_, cs_;
  std::vector<uint8_t> dead_;
  std::vector<float> tp_, tw_, ts_;                 // pins
  std::vector<int32_t> ids_;                        // the solver's grains' ids
  // the grains in the solver's order (store indices), and the ids of the grains in store order
  // it was made for
  std::vector<uint32_t> sorted_;
  std::vector<uint32_t> held_idx_;  // hold_end()
  std::vector<int32_t> members_key_, sorted_key_;
  std::vector<float> imp_j_, imp_x_, imp_n_;        // collider contacts of the substep
  std::vector<int32_t> imp_c_;
  std::unordered_map<int32_t, float> strongest_;    // id -> strongest normal impulse this frame
  // sleeping (put_to_sleep, update_sleep, sleep_on_device): per gathered grain
  std::vector<uint8_t> asleep_, can_sleep_, woken_, fast_;
  std::vector<float> sleep_time_, sleep_anchor_, sleep_accel_;
  std::vector<int32_t> sleep_contacts_;
  gr_sleep sleep_{};
  GrainsSleep sleep_in_;
  // each grain's sleeping reads along its row (gr_row_sleep), made on the device
  std::vector<uint32_t> row_words_;
  std::vector<float> awake_mass_, v_start_, P_start_;
};

}  // namespace

const GrainsSolver* grains_solver(const Node& node) {
  const GrainsNode* g = dynamic_cast<const GrainsNode*>(&node);
  return g ? &g->solver() : nullptr;
}

void register_grains_node() {
  NodeTypeInfo t;
  t.type = "grains";
  t.reports_error = true;
  t.doc = "POP Grains: position-based dynamics for grains (contacts, friction, colliders, mass-shock, clumping, explicit constraints, pins, rigid shape matching, impact data, collision feedback).";
  t.params = {
#define GR_DECL_FLOAT(name, def, meaning) ParamDecl::Float(#name, def, meaning)
#define GR_DECL_INT(name, def, meaning) ParamDecl::Int(#name, def, meaning)
#define GR_DECL_TOGGLE(name, def, meaning) ParamDecl::Toggle(#name, def, meaning)
#define GR_DECL_VECTOR(name, def, meaning) ParamDecl::Vector(#name, Vec3{GR_UNPAREN def}, meaning)
#define GR_DECL_MENU(name, def, meaning) ParamDecl::Choice(#name, def, meaning)
#define GR_DECL_STRING(name, def, meaning) ParamDecl::String(#name, def, meaning)
#define GR_PARAM(kind, name, def, home, modifiers, meaning) GR_DECL_##kind(name, def, meaning) modifiers,
#include "nodes/grains/kernels/param_table.h"
#undef GR_PARAM
  };
  t.make = [] { return std::make_unique<GrainsNode>(); };
  // gauss_seidel's flows need finer steps than its overlaps show: with the default bounds, error
  // control lets the DEM collapse and pile (1 cm grains) drop to 16-32 substeps once they slow,
  // and the column slumps to H/L0 1.51, the heap to 35 degrees. A step of r / 4 keeps 64 through
  // the flow, a resting fall of r / 256 at least 32 at rest (docs/heap-angle.md, "Gauss-Seidel
  // with carried loads").
  t.motion_bounds = [](const ParamSet& p) {
    MotionBounds b;
    if (p.choice("contact_solver") == kContactGaussSeidel) {
      b.step = 0.25;
      b.fall = 1.0 / 256;
    }
    return b;
  };
  // Refused: a parameter of the Jacobi path set with contact_solver gauss_seidel (it would have
  // no effect), and use_opencl on a machine without the device (or a GRAINS_OPENCL_DEVICE
  // naming none)
  t.check = [](const ParamSet& p, const std::string&) -> std::pair<std::string, std::string> {
    const bool gauss_seidel = p.choice("contact_solver") == kContactGaussSeidel;
    if (gauss_seidel) {
      // the Jacobi path's own, and what gauss_seidel does instead of each (gauss_seidel.cpp)
      static const std::pair<const char*, const char*> jacobi_only[] = {
          {"accurate_friction", "its friction is each contact's own Coulomb cone in every pass"},
          {"contact_memory", "it carries each contact's load from one substep to the next"},
          {"chebyshev_rho", "its passes are not Jacobi iterations"},
          {"update_collisions_during_iterations", "its contacts are found once a substep"},
          {"update_neighbors_during_iterations", "its contacts are found once a substep"},
      };
      const NodeTypeInfo* self = find_node_type("grains");
      for (const auto& [name, instead] : jacobi_only) {
        if (!p.authored(name)) continue;
        const ParamDecl* d = self->find_param(name);
        const double now = d->type == ParamType::Toggle ? (p.b(name) ? 1.0 : 0.0) : p.f(name);
        // the declared default, said again (compared as the node reads it, a float)
        if (float(now) == float(d->def[0]) && !p.is_animated(name)) continue;
        return {std::string(name) + " works with contact_solver jacobi only (gauss_seidel, the default: " +
                    instead + "); set contact_solver to jacobi or remove " + name,
                name};
      }
    }
    if (!p.b("use_opencl")) return {"", ""};
    opencl::DeviceChoice choice;
    std::string problem;
    if (!opencl::chosen_device(&choice, &problem)) return {problem, "use_opencl"};
    return {"", ""};
  };
  register_node_type(std::move(t));
}

}  // namespace grains
