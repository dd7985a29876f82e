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
#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "engine/node.h"
#include "nodes/grains/solver.h"
#include "nodes/register.h"

namespace grains {
namespace {

class GrainsNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    const ParamSet& p = ctx.params;
    if (p.f("activation") <= 0) return;
    ParticleStore& s = ctx.pts;
    const std::string& group = p.s("group");
    const int32_t* g = group.empty() ? nullptr : s.i_if(group_attribute(group));
    if (!group.empty() && !g) return;  // the group does not exist yet: no member
    idx_.clear();
    for (uint32_t k : ctx.members)
      if (!g || g[k]) idx_.push_back(k);
    size_t n = idx_.size();
    if (n == 0) return;

    GrainsSettings st = settings(p, ctx);
    float half_sep = st.particle_separation * 0.5f;
    // the solver's order: cell order at the start of each frame, or whenever the grains
    // (their ids, in store order) change; between, the same order, so that the solver may keep
    // its neighbour rows from one substep to the next
    const int32_t* id = s.i_if("id");
    members_key_.resize(n);
    for (size_t k = 0; k < n; ++k) members_key_[k] = id ? id[idx_[k]] : static_cast<int32_t>(idx_[k]);
    if (ctx.time.substep == 0 || members_key_ != sorted_key_ || sorted_.size() != n) {
      sort_by_cell(s, st, half_sep);
      sorted_ = idx_;
      sorted_key_ = members_key_;
    } else {
      idx_ = sorted_;
    }
    gather3(s.v3("P"), P_);
    gather3(s.v3("v"), v_);
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
    if (st.mass_shock == MassShock::Global) {
      shock_.assign(n, 1.0f);
      d.shockmass = shock_.data();
    }
    // explicit constraints, and rigid shape matching's connectivity: the gathered primitives
    if (st.constraint_weight > 0 || st.rigid_shape_matching) gather_constraints(s, d);
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
    const bool impacts = p.b("add_impact_data"), feedback = p.b("enable_collision_feedback");
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
    // stats only for error control: the evaluator measures each frame itself (measure_frame)
    GrainsStats stats;
    solver_.substep(d, st, ctx.colliders.data(), ctx.colliders.size(),
                    ctx.substep_error ? &stats : nullptr);
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

    float* P = s.v3("P");
    float* v = s.v3("v");
    int32_t* pbd = s.i("ispbd");
    for (size_t k = 0; k < n; ++k) {
      uint32_t i = idx_[k];
      store3(P, i, load3(P_.data(), k));
      store3(v, i, load3(v_.data(), k));
      pbd[i] = 1;
    }
    if (d.shockmass) {
      float* sm = s.f("shockmass");
      for (size_t k = 0; k < n; ++k) sm[idx_[k]] = shock_[k];
    }
  }

 private:
  GrainsSettings settings(const ParamSet& p, const CookContext& ctx) const {
    GrainsSettings st;
    st.dt = static_cast<float>(ctx.time.dt);
    // stiffness fractions k / (substeps x iterations) count the solver's own substeps, so a
    // stiffness means the same whatever error control adds
    st.substeps = ctx.time.base_substeps;
    st.keep_velocity = ctx.time.stabilize;
    st.threads = ctx.threads;
    st.constraint_iterations = p.i("constraint_iterations");
    st.particle_separation = static_cast<float>(p.f("particle_separation"));
    st.assume_uniform_radius = p.b("assume_uniform_radius");
    st.friction_with_colliders = static_cast<float>(p.f("friction_with_colliders"));
    st.friction_with_particles = static_cast<float>(p.f("friction_with_particles"));
    st.accurate_friction = p.b("accurate_friction");
    st.static_threshold = static_cast<float>(p.f("static_threshold"));
    st.scale_kinetic = static_cast<float>(p.f("scale_kinetic"));
    st.repulsion_weight = static_cast<float>(p.f("internal_collisions_weight"));
    st.repulsion_stiffness = static_cast<float>(p.f("internal_collisions_stiffness"));
    st.mass_shock = !p.b("enable_mass_shock_scaling") ? MassShock::Off
                    : p.s("mass_shock_method") == "global" ? MassShock::Global
                                                           : MassShock::Local;
    st.shock_scaling_power = static_cast<float>(p.f("shock_scaling_power"));
    st.shock_axis = p.v3("shock_axis");
    st.shock_origin = p.v3("shock_origin");
    st.clumping_weight = static_cast<float>(p.f("clumping_weight"));
    st.clumping_stiffness = static_cast<float>(p.f("clumping_stiffness"));
    st.constraint_weight = static_cast<float>(p.f("explicit_constraints_weight"));
    st.constraint_stiffness = static_cast<float>(p.f("explicit_constraints_stiffness"));
    st.collide_mutually_constrained = p.b("collide_mutually_constrained_particles");
    st.instantaneous_strain = p.b("instantaneous_strain");
    st.strain_decay = static_cast<float>(p.f("strain_decay"));
    st.break_constraints = p.b("break_constraints");
    st.break_threshold = static_cast<float>(p.f("break_threshold"));
    st.remove_strands = p.b("remove_strands");
    st.max_neighbors = p.i("max_neighbors");
    st.neighbor_query_scale = static_cast<float>(p.f("neighbor_query_scale"));
    st.max_speed = static_cast<float>(p.f("max_speed"));
    st.max_acceleration = static_cast<float>(p.f("max_acceleration"));
    st.drift_threshold = static_cast<float>(p.f("drift_threshold"));
    st.velocity_blend = static_cast<float>(p.f("velocity_blend"));
    st.over_relaxation = static_cast<float>(p.f("over_relaxation"));
    st.chebyshev_rho = static_cast<float>(p.f("chebyshev_rho"));
    st.pre_stabilization = p.b("pre_stabilization");
    st.update_collisions_during_iterations = p.b("update_collisions_during_iterations");
    st.update_neighbors_during_iterations = p.b("update_neighbors_during_iterations");
    st.final_collision_test = p.b("final_collision_test");
    st.disable_constraint_averaging = p.b("disable_constraint_averaging");
    st.target_weight = static_cast<float>(p.f("target_weight"));
    st.target_stiffness = static_cast<float>(p.f("target_stiffness"));
    st.rigid_shape_matching = p.b("enable_rigid_shape_matching");
    return st;
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
  std::vector<int32_t> members_key_, sorted_key_;
  std::vector<float> imp_j_, imp_x_, imp_n_;        // collider contacts of the substep
  std::vector<int32_t> imp_c_;
  std::unordered_map<int32_t, float> strongest_;    // id -> strongest normal impulse this frame
};

}  // namespace

void register_grains_node() {
  NodeTypeInfo t;
  t.type = "grains";
  t.reports_error = true;
  t.doc = "POP Grains: position-based dynamics for grains (contacts, friction, colliders, mass-shock, clumping, explicit constraints, pins, rigid shape matching, impact data, collision feedback).";
  t.params = {
      ParamDecl::Float("activation", 1, "the node acts only while this is greater than 0"),
      ParamDecl::String("group", "", "act only on this point group of the stream (empty: the whole stream)"),
      ParamDecl::Float("particle_separation", 0.1,
                       "mean grain diameter hint: radius of points without pscale, mass-shock length scale").positive().unit("m"),
      ParamDecl::Int("constraint_iterations", 10, "Jacobi iterations per substep; about twice the stacking height").at_least(1),
      ParamDecl::Toggle("assume_uniform_radius", true, "search every grain as the largest one, with one grid cell size: faster; for grains of one size"),
      ParamDecl::Float("friction_with_colliders", 1, "grain-collider Coulomb friction: a lab mu is this with static_threshold 1 and scale_kinetic 1")
          .at_least(0).scaled_by("friction"),
      ParamDecl::Float("friction_with_particles", 1, "grain-grain Coulomb friction: static mu = this x static_threshold, kinetic mu = this x scale_kinetic")
          .at_least(0).scaled_by("friction"),
      ParamDecl::Toggle("accurate_friction", true, "apply friction after every iteration instead of once after the loop"),
      ParamDecl::Float("static_threshold", 1, "static friction: slip under this x friction x the contact's normal correction in the substep is removed").at_least(0),
      ParamDecl::Float("scale_kinetic", 0.5, "kinetic friction: beyond it, a substep removes at most this x friction x the normal correction").at_least(0),
      ParamDecl::Float("internal_collisions_weight", 1, "weight of grain-grain collisions; 0 disables them")
          .range(0, 2).scaled_by("repulsionweight"),
      ParamDecl::Float("internal_collisions_stiffness", 1000, "stiffness of grain-grain collisions; full at substeps x iterations")
          .at_least(0).scaled_by("repulsionstiffness"),
      ParamDecl::Toggle("enable_mass_shock_scaling", false, "make higher grains lighter so stacks converge faster"),
      ParamDecl::Menu("mass_shock_method", {"global", "local"}, "global",
                      "global: write shockmass before iterating; local: pair mass ratio on the fly (power clamped near 7)"),
      ParamDecl::Float("shock_scaling_power", 1, "0: no ratio; 1: a 15% ratio between two stacked grains").at_least(0),
      ParamDecl::Vector("shock_axis", {0, 1, 0}, "up vector of the mass gradient (against gravity)"),
      ParamDecl::Vector("shock_origin", {0, 0, 0}, "rough centre of the grains; far grains clamp to min/max mass").unit("m"),
      ParamDecl::Float("clumping_weight", 0, "weight of the pull between nearby grains; 0 disables clumping")
          .range(0, 2).scaled_by("attractionweight"),
      ParamDecl::Float("clumping_stiffness", 100, "stiffness of clumping").at_least(0).scaled_by("attractionstiffness"),
      ParamDecl::Float("explicit_constraints_weight", 1,
                       "weight of the distance constraints of 2-point primitives (restlength); 0 skips them entirely")
          .range(0, 2).scaled_by("constraintweight"),
      ParamDecl::Float("explicit_constraints_stiffness", 1000,
                       "stiffness of explicit constraints; full at substeps x iterations")
          .at_least(0).scaled_by("constraintstiffness"),
      ParamDecl::Toggle("collide_mutually_constrained_particles", false,
                        "let constrained pairs collide too (needs them apart at rest)"),
      ParamDecl::Toggle("instantaneous_strain", true,
                        "strain = (length - restlength) / restlength at the end of each substep; off: it accumulates "
                        "each substep's change and fades at strain_decay"),
      ParamDecl::Float("strain_decay", 1, "rate at which accumulated strain fades (instantaneous_strain off)")
          .at_least(0).unit("1/s"),
      ParamDecl::Toggle("break_constraints", false, "remove a constraint once |strain| exceeds strength x break_threshold"),
      ParamDecl::Float("break_threshold", 0.05, "strain that breaks a constraint of strength 1 (0.05: 5% stretch)")
          .positive(),
      ParamDecl::Toggle("remove_strands", false,
                        "remove chain-only constraints (both endpoints with at most 2 constraints), until none is left"),
      ParamDecl::Int("max_neighbors", 32, "most neighbour candidates kept per grain (nearest first)").at_least(1),
      ParamDecl::Float("neighbor_query_scale", 1.5, "candidates closer than this times the summed radii; also the clumping range")
          .at_least(1),
      ParamDecl::Float("max_speed", 1e6, "cap on the reported speed (positions are not limited)").positive().unit("m/s"),
      ParamDecl::Float("max_acceleration", 1e6, "cap on the velocity change constraints cause").positive().unit("m/s^2"),
      ParamDecl::Float("drift_threshold", 0, "grains slower than this stay where they were").at_least(0).unit("m/s"),
      ParamDecl::Float("velocity_blend", 0, "blend of the new velocity with the predicted one").range(0, 1),
      ParamDecl::Float("over_relaxation", 1, "scale of the averaged corrections; above 1 converges faster").range(0, 2),
      ParamDecl::Float("chebyshev_rho", 0,
                       "Chebyshev acceleration of the iterations after the first 5 (not in POP Grains): the estimated "
                       "spectral radius of the Jacobi iteration, 0 = off; piles take 0.9-0.95, higher diverged")
          .range(0, 0.95),
      ParamDecl::Toggle("pre_stabilization", true,
                        "remove the overlap grains start a substep with, without turning it into velocity (Macklin et al. 2014 sec. 4.4)"),
      ParamDecl::Toggle("update_collisions_during_iterations", false, "re-find collider planes every iteration"),
      ParamDecl::Toggle("update_neighbors_during_iterations", false, "re-find neighbours every iteration"),
      ParamDecl::Toggle("final_collision_test", true, "a swept collision pass after the loop: no leaks through thin or moving colliders"),
      ParamDecl::Toggle("disable_constraint_averaging", false, "sum corrections instead of averaging them (momentum-preserving)"),
      ParamDecl::Float("target_weight", 1, "weight of the pull toward targetP; 0 disables pins")
          .range(0, 2).scaled_by("targetweight"),
      ParamDecl::Float("target_stiffness", 1000, "stiffness of pins; full at substeps x iterations; no targetstiffness attribute = no pin")
          .at_least(0).scaled_by("targetstiffness"),
      ParamDecl::Toggle("enable_rigid_shape_matching", false,
                        "keep each connected component (grains joined by 2-point primitives) a best-fit rigid placement of its rest shape"),
      ParamDecl::Toggle("add_impact_data", false,
                        "write impact, impactP, impactN, impactimpulse (N s), impactother (collider index) for collider contacts"),
      ParamDecl::Toggle("enable_collision_feedback", false,
                        "accumulate the force and torque the grains put on each collider (DIR/colliders.csv)"),
  };
  t.make = [] { return std::make_unique<GrainsNode>(); };
  register_node_type(std::move(t));
}

}  // namespace grains
