#include "engine/simulation.h"

#include <omp.h>
#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <stdexcept>

#include "engine/geometry_io.h"
#include "engine/motion.h"
#include "engine/neighbors.h"

namespace grains {

Simulation::~Simulation() = default;

Simulation::Simulation(const Graph& graph, int threads) : graph_(graph), threads_(threads) {
  if (threads_ > 0) omp_set_num_threads(threads_);
  node_objects_.resize(graph_.nodes.size());
  for (size_t s = 0; s < graph_.solvers.size(); ++s) {
    auto obj = std::make_unique<SimObject>();
    int solver = graph_.solvers[s];
    obj->name = graph_.nodes[solver].name;
    obj->objid = static_cast<int>(s);
    obj->solver = solver;

    // chain: post-order from the solver, inputs left to right, each node once (an explicit
    // stack: the graph is acyclic, checked at load, and a chain may be long)
    std::vector<char> seen(graph_.nodes.size(), 0);
    std::vector<std::vector<int>> streams(graph_.nodes.size());
    std::vector<std::pair<int, size_t>> stack = {{solver, 0}};  // node, next input
    seen[solver] = 1;
    while (!stack.empty()) {
      const int k = stack.back().first;
      const NodeDesc& d = graph_.nodes[k];
      const size_t i = stack.back().second++;
      if (i < d.inputs.size()) {
        if (!seen[d.inputs[i]]) {
          seen[d.inputs[i]] = 1;
          stack.push_back({d.inputs[i], 0});
        }
        continue;
      }
      stack.pop_back();
      std::set<int> st;
      for (int in : d.inputs) st.insert(streams[in].begin(), streams[in].end());
      if (d.info->role == NodeRole::Source) st = {k};  // a generator starts its own stream
      streams[k].assign(st.begin(), st.end());
      ChainNode c;
      c.node = k;
      c.streams = streams[k];
      c.impl = d.info->make ? d.info->make() : nullptr;
      c.params = ParamSet(d.info->params, d.params);
      obj->chain.push_back(std::move(c));
      node_objects_[k].add(obj.get());
    }

    for (const auto& name : SolverParams::read(obj->chain.back().params).colliders) {
      int ci = graph_.find(name);
      obj->collider_nodes.push_back(ci);
      obj->collider_params.emplace_back(graph_.nodes[ci].info->params, graph_.nodes[ci].params);
      node_objects_[ci].add(obj.get());
    }
    obj->colliders.resize(obj->collider_nodes.size());
    objects_.push_back(std::move(obj));
  }
  for (NodeObjects& no : node_objects_)
    for (const SimObject* o : no.objects) {
      if (!no.ids.empty()) no.ids += ' ', no.names += ' ';
      no.ids += std::to_string(o->objid);
      no.names += o->name;
    }
}

ExprVars Simulation::vars_for(const SimObject& obj, int node, double st) const {
  ExprVars v;
  v.ST = st;
  v.TIMESTEP = 1.0 / graph_.fps;
  v.SFPS = graph_.fps;
  v.SF = st * graph_.fps;
  v.T = st;
  v.F = v.SF + 1;
  v.OBJID = obj.objid;
  v.SNOBJ = static_cast<double>(objects_.size());
  // OBJ: this object's position among the objects the node processes; ALLOBJIDS and
  // ALLOBJNAMES: all of them (without a node, the object alone)
  if (node >= 0) {
    const NodeObjects& no = node_objects_[node];
    v.NOBJ = static_cast<double>(no.objects.size());
    v.OBJ = static_cast<double>(std::find(no.objects.begin(), no.objects.end(), &obj) - no.objects.begin());
    v.ALLOBJIDS = no.ids;
    v.ALLOBJNAMES = no.names;
  } else {
    v.ALLOBJIDS = std::to_string(obj.objid);
    v.ALLOBJNAMES = obj.name;
  }
  v.OBJNAME = obj.name;
  v.DOPNET = graph_.name;
  return v;
}

template <class F>
void Simulation::checked(int node, F&& f) {
  try {
    f();
  } catch (const ParamRangeError& e) {
    throw LoadError(graph_.file, graph_.nodes[node].pointer + "/params/" + e.param,
                    "frame " + std::to_string(frame_ + 1) + ": " + e.what());
  } catch (const BudgetError& e) {
    // bad input found while cooking, named as a load error is: the graph, the node
    throw LoadError(graph_.file, graph_.nodes[node].pointer, e.what());
  } catch (const GeometryError& e) {
    // a data file read while cooking (a source's points): its node's `file`
    const NodeDesc& d = graph_.nodes[node];
    const bool file = std::any_of(d.info->params.begin(), d.info->params.end(),
                                  [](const ParamDecl& p) { return p.name == "file"; });
    throw LoadError(graph_.file, d.pointer + (file ? "/params/file" : ""), e.what());
  }
}

void Simulation::pose_colliders(SimObject& obj, double t_end, double dt) {
  for (size_t k = 0; k < obj.collider_nodes.size(); ++k) {
    int node = obj.collider_nodes[k];
    const NodeTypeInfo* info = graph_.nodes[node].info;
    ParamSet& ps = obj.collider_params[k];
    ColliderState& c = obj.colliders[k];
    if (!obj.colliders_posed) {  // the pose at the start of the simulation
      checked(node, [&] { ps.evaluate(vars_for(obj, node, t_end - dt)); });
      info->collider(ps, graph_.base_dir, c);
    }
    Pose before = c.pose;
    checked(node, [&] { ps.evaluate(vars_for(obj, node, t_end)); });
    info->collider(ps, graph_.base_dir, c);
    c.name = graph_.nodes[node].name;
    c.prev_pose = before;
    c.dt = static_cast<float>(dt);
  }
  obj.colliders_posed = true;
}

namespace {

// the node of obj's chain that holds its points' attribute `name` (ParticleStore::hold), or null
Node* holder_of(SimObject& obj, const char* name) {
  const void* owner = obj.pts.holder(name);
  if (!owner) return nullptr;
  for (ChainNode& c : obj.chain)
    if (c.impl.get() == owner) return c.impl.get();
  return nullptr;
}

// base x the power of two that reaches at least `need`, at most `most`
int refine_to(int base, int need, int most) {
  int s = base;
  while (s < need && 2 * s <= most) s *= 2;
  return s;
}

// A position, velocity or force that is not finite stops the run where it first appears: the
// next substep would spread it to every grain it touches, and the frames would fill with NaN.
// Checked after each node of each substep, so the error names the node that made it; the frames
// already written stay. An attribute a node holds (particles.h) is not read: its holder has
// checked it. Returns the first such point's index, or -1.
long first_non_finite(const ParticleStore& pts, int threads) {
  const long n = static_cast<long>(pts.size());
  const float* arrays[3];
  const char* names[3] = {"P", "v", "force"};
  for (int a = 0; a < 3; ++a) arrays[a] = pts.held(names[a]) ? nullptr : pts.v3_if(names[a]);
  long first = n;
  // serial below 64k points: a parallel region per node per substep cost small scenes with many
  // substeps (a 50-grain stack) several times their solve on two busy cores
#pragma omp parallel for schedule(static) num_threads(threads) reduction(min : first) \
    if (n > 65536)
  for (long i = 0; i < n; ++i)
    for (const float* a : arrays)
      if (a && !(std::isfinite(a[3 * i]) && std::isfinite(a[3 * i + 1]) &&
                 std::isfinite(a[3 * i + 2])))
        first = std::min(first, i);
  return first < n ? first : -1;
}

[[noreturn]] void non_finite_error(const ParticleStore& pts, long i, const std::string& node,
                                   int frame, int substep, int substeps) {
  std::string what;
  for (const char* name : {"P", "v", "force"}) {
    const float* a = pts.v3_if(name);
    if (!a) continue;
    if (std::isfinite(a[3 * i]) && std::isfinite(a[3 * i + 1]) && std::isfinite(a[3 * i + 2]))
      continue;
    char buf[160];
    std::snprintf(buf, sizeof buf, "%s%s (%g, %g, %g)", what.empty() ? "" : ", ", name,
                  a[3 * i], a[3 * i + 1], a[3 * i + 2]);
    what += buf;
  }
  const int32_t* id = pts.i_if("id");
  throw std::runtime_error("frame " + std::to_string(frame) + ", substep " +
                           std::to_string(substep + 1) + " of " + std::to_string(substeps) +
                           ", node '" + node + "': point id " +
                           std::to_string(id ? id[i] : int32_t(i)) + " is not finite: " + what);
}

}  // namespace

// Error control (solver `error_control`, DESIGN §3): a frame starts with the count the last one
// ended with; after each substep the grains nodes report its error (CookContext::substep_error),
// and a substep whose error e is over `error_tolerance` multiplies the count by the power of two
// f with f^2 >= e / tolerance (the error falls about as dt^2), up to `max_substeps`, for the rest
// of the frame and the next ones (substep s of S continues as substep f (s + 1) of f S: the same
// moment, a finer step; its first substep stabilizes: TimeInfo::stabilize). The count also never
// falls below what the grains' motion needs (motion_substeps). The first frame starts at
// `max_substeps`, and while its substeps stay under a fifth of the tolerance it coarsens to what
// the motion needs at the first substep that ends on that grid (8 fine substeps of 256 for a
// coarse 32). A frame whose every substep stayed under a fifth of the tolerance lets the next
// frame start with half as many, down to `substeps`: the overlap a substep leaves grows about as
// dt^2, so halving the step count quadruples it, and a fifth leaves a margin. Counts are `substeps` times
// a power of two. Everything here depends only on the state, so the counts, like the frames, are
// the same for any thread count.
void Simulation::step_object(SimObject& obj) {
  ChainNode& solver_entry = obj.chain.back();
  checked(obj.solver,
          [&] { solver_entry.params.evaluate(vars_for(obj, obj.solver, frame_ / graph_.fps)); });
  const SolverParams sp = SolverParams::read(solver_entry.params);
  const int base = std::max(1, sp.substeps);
  bool control = sp.error_control;
  if (control) {  // only chains with a node that reports its error (a grains node)
    bool reports = false;
    for (const auto& c : obj.chain) reports = reports || graph_.nodes[c.node].info->reports_error;
    control = reports;
  }
  const int most = std::max(base, sp.max_substeps);
  // the tightest motion bounds the chain's nodes ask for, with their parameters at the frame's
  // start (the values its first substep evaluates them to)
  MotionBounds bounds;
  if (control)
    for (auto& c : obj.chain) {
      const NodeTypeInfo* info = graph_.nodes[c.node].info;
      if (!info->motion_bounds || &c == &solver_entry) continue;
      checked(c.node, [&] { c.params.evaluate(vars_for(obj, c.node, frame_ / graph_.fps)); });
      const MotionBounds b = info->motion_bounds(c.params);
      bounds.step = std::min(bounds.step, b.step);
      bounds.fall = std::min(bounds.fall, b.fall);
    }
  const float tolerance = static_cast<float>(sp.error_tolerance);
  // the first frame starts as fine as allowed: before the chain has run nothing is known of the
  // grains' loads, and a first substep as long as a frame can crush a column by several radii.
  // Once the fine substeps have built the loads and the forces are known it may coarsen (below):
  // settle_10k, a box of 10,000 grains dropped at rest, spent 2.4 s of 18.7 in its first frame
  // at 256 substeps with errors a twentieth of the tolerance; the DEM column, whose packing
  // overlaps by more than the tolerance, keeps all 256
  const bool first = control && obj.substeps == 0;
  if (first) obj.substeps = refine_to(base, most, most);
  int substeps = base;
  if (control)
    substeps = refine_to(
        base, std::max(obj.substeps, motion_substeps(obj.pts, graph_.fps, most, bounds)), most);
  bool refined = control && substeps > obj.substeps;
  // the first frame's fine start lasts until the grains' loads and forces are known: while its
  // substeps stay under a fifth of the tolerance, it coarsens to what their motion needs at the
  // first substep that ends on that coarser grid
  bool probing = first;

  TimeInfo time;
  time.fps = graph_.fps;
  time.base_substeps = base;
  time.frame = frame_ + 1;
  std::vector<uint32_t> members;
  obj.feedback.assign(obj.collider_nodes.size(), ColliderFeedback{});
  obj.feedback_on = false;
  float frame_error = 0;
  int taken = 0;

  const int check_threads = threads_ > 0 ? threads_ : omp_get_max_threads();
  for (int s = 0; s < substeps; ++s) {
    time.substeps = substeps;
    time.stabilize = refined;
    refined = false;
    time.substep = s;
    time.dt = 1.0 / (graph_.fps * substeps);
    time.st = frame_ / graph_.fps + s * time.dt;
    float substep_error = 0;
    ParticleStore& pts = obj.pts;
    std::fill(pts.v3("force"), pts.v3("force") + 3 * pts.size(), 0.0f);
    std::fill(pts.i("ispbd"), pts.i("ispbd") + pts.size(), 0);
    pose_colliders(obj, time.st + time.dt, time.dt);

    for (auto& c : obj.chain) {
      const NodeDesc& d = graph_.nodes[c.node];
      ExprVars vars = vars_for(obj, c.node, time.st);
      if (&c != &solver_entry) checked(c.node, [&] { c.params.evaluate(vars); });
      if (!c.impl) continue;
      // members: the points of this node's streams (every point when it has none)
      members.clear();
      bool all = c.streams.empty();
      if (all) {
        members.resize(pts.size());
        for (size_t k = 0; k < pts.size(); ++k) members[k] = static_cast<uint32_t>(k);
      } else {
        const int32_t* sid = pts.i("streamid");
        for (size_t k = 0; k < pts.size(); ++k)
          if (std::binary_search(c.streams.begin(), c.streams.end(), sid[k]))
            members.push_back(static_cast<uint32_t>(k));
        all = members.size() == pts.size();
      }
      CookContext ctx{pts,
                      c.params,
                      time,
                      obj.colliders,
                      members,
                      all,
                      d.info->role == NodeRole::Source ? c.node : -1,
                      threads_,
                      graph_.seed * 1000003ULL + static_cast<uint64_t>(c.node),
                      d.name,
                      graph_.base_dir,
                      &obj.feedback,
                      &obj.feedback_on,
                      &vars,
                      control ? &substep_error : nullptr,
                      max_points_};
      checked(c.node, [&] { c.impl->cook(ctx); });  // a node may evaluate its own (target)
      if (const long bad = first_non_finite(pts, check_threads); bad >= 0)
        non_finite_error(pts, bad, d.name, frame_ + 1, s, substeps);
    }
    ++taken;
    frame_error = std::max(frame_error, substep_error);
    // what the grains' motion asks of the rest of the frame (read by both rules below)
    const int need = control && s + 1 < substeps
                         ? motion_substeps(pts, graph_.fps, most, bounds, holder_of(obj, "v"))
                         : 0;
    if (probing && s + 1 < substeps) {
      const int coarse = refine_to(base, need, most);
      if (!(frame_error < 0.2f * tolerance) || coarse >= substeps) {
        probing = false;
      } else if ((s + 1) % (substeps / coarse) == 0) {
        s = (s + 1) / (substeps / coarse) - 1;  // the loop's ++s: the same moment, coarser
        substeps = coarse;
        probing = false;
        continue;
      }
    }
    if (control && s + 1 < substeps) {
      // the error falls about as dt^2: refine by the power of two whose square covers it, and
      // at least as far as the grains' motion asks
      int factor = 1;
      while (substeps * factor * 2 <= most &&
             (static_cast<double>(factor) * factor * tolerance < substep_error ||
              substeps * factor < need))
        factor *= 2;
      s = factor * (s + 1) - 1;  // the loop's ++s: the same moment in the finer grid
      substeps *= factor;
      refined = factor > 1;
    }
  }
  // what a node left held between the substeps (particles.h) comes back once, for the frame
  obj.pts.fetch_held();
  if (control)
    obj.substeps = frame_error < 0.2f * tolerance && substeps > base ? substeps / 2 : substeps;
  obj.stats = FrameStats{};
  obj.stats.substeps = taken;
  obj.stats.error = frame_error;
  // feedback: the frame's impulse over the frame's length is its mean force
  if (obj.feedback_on)
    for (size_t k = 0; k < obj.feedback.size(); ++k)
      obj.stats.colliders.push_back({graph_.nodes[obj.collider_nodes[k]].name,
                                     obj.feedback[k].impulse * static_cast<float>(graph_.fps),
                                     obj.feedback[k].angular_impulse * static_cast<float>(graph_.fps)});
}

namespace {

void save_points(StateWriter& w, const ParticleStore& pts) {
  w.section("points");
  w.value<uint64_t>(pts.size());
  w.value(pts.next_id());
  w.value<uint64_t>(pts.attributes().size());
  for (const auto& [name, a] : pts.attributes()) {
    w.text(name);
    w.value(a.type);
    w.array(a.f);
    w.array(a.i);
  }
  w.array(pts.prim_points());
  w.value<uint64_t>(pts.prim_attributes().size());
  for (const auto& [name, vals] : pts.prim_attributes()) {
    w.text(name);
    w.array(vals);
  }
}

ParticleStore load_points(StateReader& r) {
  r.section("points");
  ParticleStore pts;
  const uint64_t n = r.value<uint64_t>();
  const int32_t next_id = r.value<int32_t>();
  std::vector<float> f;
  std::vector<int32_t> i;
  std::vector<std::pair<std::string, Attribute>> attributes;
  for (uint64_t k = r.value<uint64_t>(); k > 0; --k) {
    std::string name = r.text();
    Attribute a;
    r.value(a.type);
    if (a.type != AttribType::Float && a.type != AttribType::Int && a.type != AttribType::Vec3)
      r.fail("attribute '" + name + "' has an unknown type");
    r.array(a.f);
    r.array(a.i);
    for (size_t k = 0; k < a.f.size(); ++k)
      if (!std::isfinite(a.f[k]))
        r.fail("attribute '" + name + "' of point " + std::to_string(k / a.components()) +
               " is not finite");
    const size_t want_f = a.type == AttribType::Int ? 0 : n * a.components();
    const size_t want_i = a.type == AttribType::Int ? n : 0;
    if (a.f.size() != want_f || a.i.size() != want_i)
      r.fail("attribute '" + name + "' does not hold " + std::to_string(n) + " points");
    attributes.emplace_back(std::move(name), std::move(a));
  }
  // every store holds positions; their size bounds n by the file's (add_points allocates n)
  if (std::none_of(attributes.begin(), attributes.end(), [](const auto& a) {
        return a.first == "P" && a.second.type == AttribType::Vec3;
      }))
    r.fail("the points have no positions");
  pts.add_points(n);
  for (auto& [name, a] : attributes) {
    Attribute& into = pts.add(name, a.type);
    into.f = std::move(a.f);
    into.i = std::move(a.i);
  }
  // what a point file's reader refuses (geometry_io.cpp) is refused here too: the solvers index
  // by these and take ids to be unique
  if (const int32_t* id = pts.i_if("id"); id && n > 0) {
    std::vector<int32_t> ids(id, id + n);
    std::sort(ids.begin(), ids.end());
    if (auto dup = std::adjacent_find(ids.begin(), ids.end()); dup != ids.end())
      r.fail("duplicate point id " + std::to_string(*dup));
    if (next_id <= ids.back())
      r.fail("its next point id " + std::to_string(next_id) + " is not above every id (" +
             std::to_string(ids.back()) + ")");
  }
  pts.set_next_id(next_id);
  std::vector<int32_t> prims;
  r.array(prims);
  if (prims.size() % 2) r.fail("primitives must have two points each");
  for (size_t k = 0; k < prims.size(); ++k)
    if (prims[k] < 0 || static_cast<uint64_t>(prims[k]) >= n)
      r.fail("primitive " + std::to_string(k / 2) + ": point " + std::to_string(prims[k]) +
             " is out of range (" + std::to_string(n) + " points)");
  for (size_t p = 0; p + 1 < prims.size(); p += 2) pts.add_prim(prims[p], prims[p + 1]);
  for (uint64_t k = r.value<uint64_t>(); k > 0; --k) {
    const std::string name = r.text();
    std::vector<float> vals;
    r.array(vals);
    if (vals.size() != prims.size() / 2)
      r.fail("primitive attribute '" + name + "' does not hold every primitive");
    for (size_t k = 0; k < vals.size(); ++k)
      if (!std::isfinite(vals[k]))
        r.fail("primitive attribute '" + name + "' of primitive " + std::to_string(k) +
               " is not finite");
    std::copy(vals.begin(), vals.end(), pts.prim_f(name));
  }
  return pts;
}

}  // namespace

void Simulation::save_state(StateWriter& w) const {
  w.section("simulation");
  w.value(frame_);
  w.value<uint64_t>(objects_.size());
  for (const auto& o : objects_) {
    w.section("object");
    w.text(o->name);
    save_points(w, o->pts);
    w.value(o->substeps);
    w.value(o->colliders_posed);
    w.value<uint64_t>(o->colliders.size());
    for (const ColliderState& c : o->colliders) {
      w.value(c.pose);
      w.value(c.prev_pose);
      w.value(c.dt);
    }
    w.value<uint64_t>(o->chain.size());
    for (const ChainNode& c : o->chain) {
      w.text(graph_.nodes[c.node].name);
      if (c.impl) c.impl->save_state(w);
    }
  }
}

void Simulation::load_state(StateReader& r) {
  r.section("simulation");
  r.value(frame_);
  if (frame_ < 0) r.fail("a negative frame count");
  if (r.value<uint64_t>() != objects_.size())
    r.fail("it was saved for another number of solvers than the graph has");
  for (auto& o : objects_) {
    r.section("object");
    if (const std::string name = r.text(); name != o->name)
      r.fail("it holds solver '" + name + "' where the graph has '" + o->name + "'");
    o->pts = load_points(r);
    r.value(o->substeps);
    r.value(o->colliders_posed);
    if (r.value<uint64_t>() != o->colliders.size())
      r.fail("solver '" + o->name + "' had another number of colliders");
    for (ColliderState& c : o->colliders) {
      r.value(c.pose);
      r.value(c.prev_pose);
      r.value(c.dt);
    }
    if (r.value<uint64_t>() != o->chain.size())
      r.fail("solver '" + o->name + "' had another chain of nodes");
    for (ChainNode& c : o->chain) {
      if (const std::string name = r.text(); name != graph_.nodes[c.node].name)
        r.fail("solver '" + o->name + "' had node '" + name + "' where the graph has '" +
               graph_.nodes[c.node].name + "'");
      if (c.impl) c.impl->load_state(r);
    }
  }
}

std::string frame_detail(const FrameStats& s) {
  return fmt::format(
      "{} points, {} constraints, {} substeps, error {:.3g}, kinetic energy {:.4g} J, "
      "max_penetration {:.4f}, {:.1f} ms",
      s.points, s.constraints, s.substeps, s.error, s.kinetic_energy, s.max_penetration,
      s.wall_ms);
}

double precise_reach(float r, float fraction) {
  // floats in [2^e, 2^(e+1)) are 2^(e-23) apart: the largest e with 2^(e-23) <= fraction * r
  return std::ldexp(1.0, static_cast<int>(std::floor(std::log2(double(fraction) * r))) + 24);
}

void Simulation::step_frame() {
  for (auto& o : objects_) {
    auto t0 = std::chrono::steady_clock::now();
    step_object(*o);
    auto t1 = std::chrono::steady_clock::now();
    o->stats.frame = frame_ + 1;
    o->stats.time = (frame_ + 1) / graph_.fps;
    measure_frame(o->pts, o->stats);
    o->stats.wall_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
    const FrameStats& st = o->stats;
    if (st.min_radius > 0 && st.resolution >= kCoarsestResolution * st.min_radius) {
      char buf[400];
      std::snprintf(buf, sizeof buf,
                    "frame %d, solver '%s': a point lies %.4g m from the origin, where a float "
                    "resolves only %.3g m, %.3g times the smallest grain radius %.3g m: grains "
                    "there cannot be told apart; keep the scene within %.4g m of the origin",
                    frame_ + 1, o->name.c_str(), st.max_coordinate, st.resolution,
                    st.resolution / st.min_radius, st.min_radius,
                    precise_reach(st.min_radius, kCoarsestResolution));
      throw std::runtime_error(buf);
    }
  }
  ++frame_;
}

namespace {

// Penetration statistics of touching pairs: the largest overlap / (r_i + r_j), and the sum and
// count for the mean.
struct PenetrationSums {
  double sum = 0;
  size_t count = 0;
  float max = 0;
  void add(float pen) {
    max = std::max(max, pen);
    sum += pen;
    ++count;
  }
};

// Penetration of spheres of one radius r, without neighbour lists: a counting sort into cells 2r
// wide, then each point, in cell order, scans the 3 x 3 runs of 3 cells along x around its own
// for partners later in that order (each pair once). Positions are copied in cell order, so
// the scans read contiguous memory, and the scan does not branch on whether a pair touches
// (unpredictable), so the compiler vectorises it. Points are taken in fixed blocks whose sums
// are added in block order, so the result is the same for any thread count. Memory is six
// numbers per point plus the cells. Returns false, having measured nothing, when the box would
// need more than 8 cells per point (sparse outliers): the caller then uses the general search.
// (It had taken 8.7-10.6% of `grains run`'s CPU on a settled 100k pile when it scanned in
// point order with a branch per pair.)
bool penetration_uniform(const float* P, size_t n, float r, PenetrationSums& total) {
  const float inf = std::numeric_limits<float>::infinity();
  float lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf};
  for (size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a)
      if (std::isfinite(P[3 * i + a])) lo[a] = std::min(lo[a], P[3 * i + a]), hi[a] = std::max(hi[a], P[3 * i + a]);
  const double h = 2.0 * double(r);
  // every axis must have a finite range (one with no finite coordinate has lo > hi)
  if (!(h > 0) || !(lo[0] <= hi[0]) || !(lo[1] <= hi[1]) || !(lo[2] <= hi[2])) return false;
  int64_t dim[3];
  double cells = 1;
  for (int a = 0; a < 3; ++a) {
    const double span = (double(hi[a]) - lo[a]) / h;
    if (!(span < 1e15)) return false;  // the general search then; no overflowing cast
    dim[a] = int64_t(span) + 1;
    cells *= double(dim[a]);
  }
  if (cells > 8.0 * double(n) + 64) return false;
  auto coord = [&](size_t i, int a) {
    const double u = (double(P[3 * i + a]) - lo[a]) / h;
    return u >= 0 ? std::min<int64_t>(int64_t(u), dim[a] - 1) : int64_t(0);
  };
  const uint32_t none = UINT32_MAX;
  std::vector<uint32_t> key(n), start(size_t(cells) + 1, 0);
  for (size_t i = 0; i < n; ++i) {
    bool finite = std::isfinite(P[3 * i]) && std::isfinite(P[3 * i + 1]) && std::isfinite(P[3 * i + 2]);
    key[i] = finite ? uint32_t((coord(i, 2) * dim[1] + coord(i, 1)) * dim[0] + coord(i, 0)) : none;
    if (key[i] != none) ++start[key[i] + 1];
  }
  for (size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
  const size_t m = start.back();  // finite points
  std::vector<float> X(m), Y(m), Z(m);
  std::vector<uint32_t> cell_of(m);
  {
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t i = 0; i < n; ++i)
      if (key[i] != none) {
        const uint32_t s = fill[key[i]]++;
        X[s] = P[3 * i], Y[s] = P[3 * i + 1], Z[s] = P[3 * i + 2];
        cell_of[s] = key[i];
      }
  }
  const float rsum = 2.0f * r, inv_rsum = 1.0f / rsum;
  constexpr size_t kBlock = 1024;
  const ptrdiff_t blocks = ptrdiff_t((m + kBlock - 1) / kBlock);
  std::vector<PenetrationSums> part(static_cast<size_t>(blocks));
#pragma omp parallel for schedule(dynamic, 1)
  for (ptrdiff_t b = 0; b < blocks; ++b) {
    PenetrationSums acc;
    for (size_t s = size_t(b) * kBlock; s < std::min(m, size_t(b + 1) * kBlock); ++s) {
      const int64_t key_s = cell_of[s];
      const int64_t cx = key_s % dim[0], cy = key_s / dim[0] % dim[1], cz = key_s / dim[0] / dim[1];
      const int64_t x0 = std::max<int64_t>(cx - 1, 0), x1 = std::min(cx + 1, dim[0] - 1);
      const float px = X[s], py = Y[s], pz = Z[s];
      for (int64_t z = std::max<int64_t>(cz - 1, 0); z <= std::min(cz + 1, dim[2] - 1); ++z)
        for (int64_t y = std::max<int64_t>(cy - 1, 0); y <= std::min(cy + 1, dim[1] - 1); ++y) {
          const size_t row = size_t((z * dim[1] + y) * dim[0]);
          const size_t k0 = std::max<size_t>(start[row + x0], s + 1), k1 = start[row + x1 + 1];
          float sum = 0, count = 0, mx = 0;
          for (size_t k = k0; k < k1; ++k) {
            const float dx = px - X[k], dy = py - Y[k], dz = pz - Z[k];
            const float pen = (rsum - std::sqrt(dx * dx + dy * dy + dz * dz)) * inv_rsum;
            const bool touching = pen > 0;
            sum += touching ? pen : 0.0f;
            count += touching ? 1.0f : 0.0f;
            mx = std::max(mx, touching ? pen : 0.0f);
          }
          acc.sum += sum;
          acc.count += size_t(count);
          acc.max = std::max(acc.max, mx);
        }
    }
    part[size_t(b)] = acc;
  }
  for (const PenetrationSums& p : part) {
    total.max = std::max(total.max, p.max);
    total.sum += p.sum;
    total.count += p.count;
  }
  return true;
}

}  // namespace

void measure_frame(const ParticleStore& pts, FrameStats& st) {
  size_t n = pts.size();
  st.points = n;
  st.constraints = pts.prim_count();
  const float* v = pts.v3_if("v");
  const float* m = pts.f_if("mass");
  double ke = 0;
  for (size_t k = 0; k < n; ++k) {
    Vec3 vk = load3(v, k);
    ke += 0.5 * (m ? m[k] : 1.0) * dot(vk, vk);
  }
  st.kinetic_energy = ke;
  // precision: the largest coordinate, the float spacing there, the smallest radius
  st.max_coordinate = st.min_radius = 0;
  if (const float* P = pts.v3_if("P"))
    for (size_t k = 0; k < 3 * n; ++k) st.max_coordinate = std::max(st.max_coordinate, std::fabs(P[k]));
  st.resolution = std::nextafter(st.max_coordinate, std::numeric_limits<float>::infinity()) -
                  st.max_coordinate;
  if (const float* r = pts.f_if("pscale")) {
    float least = std::numeric_limits<float>::infinity();
    for (size_t k = 0; k < n; ++k)
      if (r[k] > 0) least = std::min(least, r[k]);
    st.min_radius = std::isfinite(least) ? least : 0;
  } else if (n > 0) {
    st.min_radius = find_known_attribute("pscale")->value[0];
  }
  st.max_strain = 0;
  if (const float* strain = pts.prim_f_if("strain"))
    for (size_t p = 0; p < pts.prim_count(); ++p)
      st.max_strain = std::max(st.max_strain, std::fabs(strain[p]));
  // penetration over touching pairs
  const float* P = pts.v3_if("P");
  const float* r = pts.f_if("pscale");
  if (n < 2 || !P || !r) {
    st.max_penetration = st.mean_penetration = 0;
    return;
  }
  PenetrationSums pen;
  bool uniform = true;
  for (size_t k = 1; k < n && uniform; ++k) uniform = r[k] == r[0];
  if (uniform && penetration_uniform(P, n, r[0], pen)) {
    st.max_penetration = pen.max;
    st.mean_penetration = pen.count ? static_cast<float>(pen.sum / pen.count) : 0.0f;
    return;
  }
  NeighborSearch search;
  NeighborList nl;
  NeighborQuery q;
  q.query_scale = 1.0f;
  q.max_neighbors = 0;
  q.uniform_radius = uniform;
  search.find(P, r, n, q, nl);
  for (size_t i = 0; i < n; ++i)
    for (uint32_t e = nl.offsets[i]; e < nl.offsets[i + 1]; ++e) {
      uint32_t j = nl.indices[e];
      if (j <= i) continue;
      float rr = r[i] + r[j];
      float d = length(load3(P, i) - load3(P, j));
      float p = (rr - d) / rr;
      if (p > 0) pen.add(p);
    }
  st.max_penetration = pen.max;
  st.mean_penetration = pen.count ? static_cast<float>(pen.sum / pen.count) : 0.0f;
}

}  // namespace grains
