// A small harness for the grains solver tests: grains as parallel arrays, gravity as a force
// (force = mass * g, as the POP solver's force nodes would write it), collider states whose
// poses advance with the substeps, and a loop that calls GrainsSolver::substep.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <vector>

#include "engine/collider.h"
#include "engine/mesh_shape.h"
#include "engine/state_stream.h"
#include "nodes/grains/solver.h"
#include "tests/support/meshes.h"
#include "tests/support/support.h"

namespace grains::test {

constexpr float kG = 9.81f;

// prints a measured number when GRAINS_VERBOSE is set (the report quotes these)
inline void report(const char* what, double value) {
  if (std::getenv("GRAINS_VERBOSE")) std::printf("  [grains] %-60s %.6g\n", what, value);
}

inline GrainsSettings settings(float fps, int substeps, int iterations) {
  GrainsSettings s;
  s.substeps = substeps;
  s.dt = 1.0f / (fps * static_cast<float>(substeps));
  s.constraint_iterations = iterations;
  // One thread: `make test` runs two test processes on two cores, and two 2-thread teams wait at
  // every barrier for a partner the other process has descheduled (the 50-grain column took 36 s
  // beside another test instead of 0.16 s alone). Output is bit-identical for any thread count;
  // the determinism tests run 1 and 2 threads explicitly.
  s.threads = 1;
  return s;
}

inline ColliderState ground(float y = 0.0f) {
  ColliderState c;
  c.name = "ground";
  c.shape.kind = ShapeKind::Plane;
  c.pose.t = {0, y, 0};
  c.prev_pose = c.pose;
  return c;
}

// The plane y = 0 rotated about z by `deg` degrees: normal (-sin, cos, 0); a grain on it slides
// toward -(cos, sin, 0).
inline ColliderState incline(float deg) {
  ColliderState c;
  c.name = "incline";
  c.shape.kind = ShapeKind::Plane;
  c.pose = Pose::from_trs({0, 0, 0}, {0, 0, deg}, 1.0f);
  c.prev_pose = c.pose;
  return c;
}

inline ColliderState box(const Vec3& centre, const Vec3& size) {
  ColliderState c;
  c.name = "box";
  c.shape.kind = ShapeKind::Box;
  c.shape.size = size;
  c.pose.t = centre;
  c.prev_pose = c.pose;
  return c;
}

struct Scene {
  std::vector<float> P, v, force, mass, pscale, shockmass;
  std::vector<float> friction;  // optional, empty = missing
  std::vector<int32_t> ids;     // optional (GrainsData::id), empty = missing
  // explicit constraints: (m x 2) grain indices with per-primitive attributes; primitives the
  // solver marks dead (broken, strands) are removed after each substep, as the node does
  std::vector<int32_t> prims;
  std::vector<float> restlength, strength, strain;
  std::vector<float> constraintweight;  // optional, empty = missing
  size_t removed = 0;                   // primitives removed so far
  std::vector<float> targetP, targetstiffness;  // pins, optional (empty targetstiffness = no pin)
  std::vector<ColliderState> colliders;
  // collider motion: the pose of collider c at time t (unset = static)
  std::vector<std::function<Pose(float)>> collider_motion;
  GrainsSettings s;
  GrainsSolver solver;
  Vec3 gravity{0, -kG, 0};
  std::vector<Vec3> extra_force;  // per grain, added to mass * gravity (optional)
  float time = 0;
  GrainsStats stats;
  bool with_stats = true;  // the solver gives stats (error control's overlap statistics)
  bool hold_end = false;   // GrainsData::may_hold_end and start_held (substep())
  // impact data (GrainsData::impact_*), kContactSlots a grain, when `impacts` is set
  bool impacts = false;
  std::vector<float> impact_impulse, impact_point, impact_normal;
  std::vector<int32_t> impact_collider;
  std::vector<uint8_t> dead;

  size_t size() const { return mass.size(); }
  size_t add(const Vec3& p, float r, float m = 1.0f, const Vec3& vel = {0, 0, 0}) {
    // push_back, not insert({...}): GCC 12 warns falsely (-Wstringop-overflow) on the latter
    for (float c : {p.x, p.y, p.z}) P.push_back(c);
    for (float c : {vel.x, vel.y, vel.z}) v.push_back(c);
    for (int c = 0; c < 3; ++c) force.push_back(0.0f);
    mass.push_back(m);
    pscale.push_back(r);
    shockmass.push_back(0);
    return mass.size() - 1;
  }
  // a constraint between a and b; rest length = their distance now unless given
  size_t connect(size_t a, size_t b, float rest = -1, float str = 1) {
    prims.insert(prims.end(), {static_cast<int32_t>(a), static_cast<int32_t>(b)});
    restlength.push_back(rest >= 0 ? rest : length(pos(a) - pos(b)));
    strength.push_back(str);
    strain.push_back(0);
    return restlength.size() - 1;
  }
  size_t prim_count() const { return restlength.size(); }
  Vec3 pos(size_t i) const { return {P[3 * i], P[3 * i + 1], P[3 * i + 2]}; }
  Vec3 vel(size_t i) const { return {v[3 * i], v[3 * i + 1], v[3 * i + 2]}; }
  void set_vel(size_t i, const Vec3& u) {
    v[3 * i] = u.x;
    v[3 * i + 1] = u.y;
    v[3 * i + 2] = u.z;
  }
  void add_collider(const ColliderState& c, std::function<Pose(float)> motion = nullptr) {
    colliders.push_back(c);
    collider_motion.push_back(std::move(motion));
  }

  GrainsData data() {
    GrainsData d;
    d.n = size();
    d.P = P.data();
    d.v = v.data();
    d.force = force.data();
    d.mass = mass.data();
    d.pscale = pscale.data();
    d.friction = friction.empty() ? nullptr : friction.data();
    d.shockmass = shockmass.data();
    d.id = ids.empty() ? nullptr : ids.data();
    d.prim_count = prim_count();
    d.prim_points = prims.data();
    d.restlength = restlength.data();
    d.strength = strength.data();
    d.strain = strain.data();
    dead.assign(prim_count(), 0);
    d.prim_dead = dead.data();
    d.constraintweight = constraintweight.empty() ? nullptr : constraintweight.data();
    if (!targetstiffness.empty()) {
      d.targetP = targetP.data();
      d.targetstiffness = targetstiffness.data();
    }
    if (impacts) {
      const size_t slots = GrainsSolver::kContactSlots * size();
      for (std::vector<float>* a : {&impact_impulse, &impact_point, &impact_normal})
        a->assign(3 * slots, 0.0f);
      impact_collider.assign(slots, -1);
      d.impact_impulse = impact_impulse.data();
      d.impact_point = impact_point.data();
      d.impact_normal = impact_normal.data();
      d.impact_collider = impact_collider.data();
    }
    return d;
  }

  void substep() {
    for (size_t i = 0; i < size(); ++i) {
      Vec3 f = gravity * mass[i];
      if (!extra_force.empty()) f += extra_force[i];
      force[3 * i] = f.x;
      force[3 * i + 1] = f.y;
      force[3 * i + 2] = f.z;
    }
    for (size_t c = 0; c < colliders.size(); ++c) {
      colliders[c].dt = s.dt;
      if (collider_motion[c]) {
        colliders[c].prev_pose = collider_motion[c](time);
        colliders[c].pose = collider_motion[c](time + s.dt);
      }
    }
    GrainsData d = data();
    // use_opencl: the end may stay on the device, and a held end is the next start (P and v
    // are then not read; the caller brings them back through the solver)
    d.may_hold_end = hold_end;
    d.start_held = hold_end && solver.end_held();
    solver.substep(d, s, colliders.data(), colliders.size(), with_stats ? &stats : nullptr);
    remove_dead();
    time += s.dt;
  }
  void run(float seconds) {
    int steps = static_cast<int>(std::lround(seconds / s.dt));
    for (int k = 0; k < steps; ++k) substep();
  }
  void remove_dead() {
    size_t kept = 0;
    for (size_t q = 0; q < prim_count(); ++q) {
      if (dead[q]) continue;
      prims[2 * kept] = prims[2 * q];
      prims[2 * kept + 1] = prims[2 * q + 1];
      restlength[kept] = restlength[q];
      strength[kept] = strength[q];
      strain[kept] = strain[q];
      ++kept;
    }
    removed += prim_count() - kept;
    prims.resize(2 * kept);
    restlength.resize(kept);
    strength.resize(kept);
    strain.resize(kept);
  }
  float max_abs_strain() const {
    float m = 0;
    for (float e : strain) m = std::max(m, std::fabs(e));
    return m;
  }
  float max_y() const {
    float m = -1e30f;
    for (size_t i = 0; i < size(); ++i) m = std::max(m, P[3 * i + 1]);
    return m;
  }
  Vec3 centroid() const {
    Vec3 c;
    for (size_t i = 0; i < size(); ++i) c += pos(i);
    return c / static_cast<float>(size());
  }
  // an nx x ny x nz block of grains of radius r, 2r apart from the origin corner with the bottom
  // layer resting on y = 0, each coordinate jittered by up to +-0.005 m (a fixed sequence)
  void add_jittered_block(int nx, int ny, int nz, float r) {
    Sequence seq;
    auto jitter = [&seq]() { return (seq.next() - 0.5f) * 0.01f; };
    for (int x = 0; x < nx; ++x)
      for (int y = 0; y < ny; ++y)
        for (int z = 0; z < nz; ++z)
          add({x * 2 * r + jitter(), r + y * 2 * r + jitter(), z * 2 * r + jitter()}, r);
  }
};

// An m x m x m cube of touching grains (r = 0.05; m = 10: side 1 m), each joined to its +x, +y, +z
// neighbours by a primitive (rigid shape matching's connectivity: the caller sets the settings,
// with explicit constraint weight 0 the primitives hold nothing by themselves), tilted 20 and 10
// degrees, its centre height + 0.9 m above the ground; rest (when set) receives each grain's
// place in the untilted cube.
inline Scene connected_cube(float height, std::vector<Vec3>* rest = nullptr, int m = 10) {
  Scene sc;
  sc.add_collider(ground());
  const float r = 0.05f, half = 0.5f * float(m - 1);
  const Pose tilt = Pose::from_trs({0, height + 0.9f, 0}, {20, 0, 10}, 1.0f);
  auto index = [&](int a, int b, int c) { return (a * m + b) * m + c; };
  for (int a = 0; a < m; ++a)
    for (int b = 0; b < m; ++b)
      for (int c = 0; c < m; ++c) {
        const Vec3 local{(a - half) * 2 * r, (b - half) * 2 * r, (c - half) * 2 * r};
        if (rest) rest->push_back(local);
        sc.add(tilt.apply(local), r);
      }
  for (int a = 0; a < m; ++a)
    for (int b = 0; b < m; ++b)
      for (int c = 0; c < m; ++c) {
        if (a + 1 < m) sc.connect(index(a, b, c), index(a + 1, b, c));
        if (b + 1 < m) sc.connect(index(a, b, c), index(a, b + 1, c));
        if (c + 1 < m) sc.connect(index(a, b, c), index(a, b, c + 1));
      }
  return sc;
}

// The contact-list tests' scene (gauss_seidel keeps its list while the neighbour rows are kept),
// layered_block before its fall, layered_drop after: 512 grains of radius 0.04 m in layers half a
// radius apart, a little jittered sideways, fall onto the ground at 8 x 10 for 96 substeps (the
// fall moves the rows, the rest keeps them), the solver's state written and read back after every
// substep when `round_trip` (a checkpoint, which drops the list). Returns the scene; *kept is the
// substeps that kept the list. max_neighbors > 0 cuts the rows at that many candidates (the Verlet
// skin is then the cut rows' reach).
inline Scene layered_block(bool use_opencl, int max_neighbors = 0) {
  Scene sc;
  sc.s = settings(24, 8, 10);
  if (max_neighbors > 0) sc.s.max_neighbors = max_neighbors;
  sc.s.contact_solver = kContactGaussSeidel;
  sc.s.use_opencl = use_opencl;
  sc.add_collider(ground());
  Sequence seq;
  for (int a = 0; a < 8; ++a)
    for (int b = 0; b < 8; ++b)
      for (int c = 0; c < 8; ++c)
        sc.add({0.081f * a + 0.001f * seq.next(), 0.045f + 0.1f * b,
                0.081f * c + 0.001f * seq.next()},
               0.04f);
  return sc;
}
inline Scene layered_drop(bool use_opencl, bool round_trip, size_t* kept, int max_neighbors = 0) {
  Scene sc = layered_block(use_opencl, max_neighbors);
  for (int k = 0; k < 96; ++k) {
    sc.substep();
    if (round_trip) {
      StateWriter w;
      sc.solver.save_state(w);
      StateReader r(w.bytes(), "round trip");
      sc.solver.load_state(r);
    }
  }
  *kept = sc.solver.contact_lists_kept();
  return sc;
}

// 16 grains (r = 4 cm) shot down at 30 m/s at a plate 1 cm thick (its top at y = 0.005 m, wider
// than the grains), each above a fixed grain hanging under the plate: gauss_seidel on the OpenCL
// device. The plate is an analytic box, or with `mesh` the same box as a triangle mesh.
inline Scene shot_plate(bool mesh) {
  const float r = 0.04f, top = 0.005f;
  Scene sc;
  sc.s = settings(24, 10, 10);
  sc.s.contact_solver = kContactGaussSeidel;
  sc.s.use_opencl = true;
  const Vec3 centre{0.15f, 0.0f, 0.15f}, size{2.0f, 2 * top, 2.0f};
  ColliderState plate = box(centre, size);
  if (mesh) {
    std::string problem;
    plate.shape.kind = ShapeKind::Mesh;
    plate.shape.mesh = MeshShape::build(box_mesh({0, 0, 0}, size), &problem);
  }
  sc.add_collider(plate);
  for (int a = 0; a < 4; ++a)
    for (int c = 0; c < 4; ++c) {
      sc.add({0.1f * a, 0.06f, 0.1f * c}, r, 1.0f, {0.0f, -30.0f, 0.0f});
      sc.add({0.1f * a, -0.1f, 0.1f * c}, r, 0.0f);  // fixed
    }
  return sc;
}

// the grains of `sc` in the order `order` (new grain k: old grain order[k]), or with grains
// killed (left out of `order`) and born (order[k] >= size: a grain near `born`, falling, with a
// fresh id)
inline void reorder(Scene& sc, const std::vector<size_t>& order, const Vec3& born) {
  const std::vector<float> P = sc.P, v = sc.v, mass = sc.mass, pscale = sc.pscale;
  const std::vector<int32_t> ids = sc.ids;
  const size_t was = mass.size();
  auto take3 = [&](std::vector<float>& to, const std::vector<float>& from, size_t k, size_t j,
                   const Vec3& fresh) {
    const Vec3 x = j < was ? Vec3{from[3 * j], from[3 * j + 1], from[3 * j + 2]} : fresh;
    to[3 * k] = x.x, to[3 * k + 1] = x.y, to[3 * k + 2] = x.z;
  };
  const size_t n = order.size();
  sc.P.assign(3 * n, 0.0f), sc.v.assign(3 * n, 0.0f), sc.force.assign(3 * n, 0.0f);
  sc.mass.assign(n, 1.0f), sc.pscale.assign(n, 0.04f), sc.shockmass.assign(n, 0.0f);
  sc.ids.assign(n, 0);
  int32_t next = *std::max_element(ids.begin(), ids.end()) + 1;
  for (size_t k = 0; k < n; ++k) {
    const size_t j = order[k];
    take3(sc.P, P, k, j, born + Vec3{0.09f * float(k % 8), 0.0f, 0.09f * float(k / 8 % 8)});
    take3(sc.v, v, k, j, Vec3{0.01f * float(k % 7), -0.5f, 0.0f});  // not one word over and over
    if (j < was) sc.mass[k] = mass[j], sc.pscale[k] = pscale[j];
    sc.ids[k] = j < was ? ids[j] : next++;
  }
}

// new orders for reorder(): n grains in blocks of 64, each reversed, in reverse; and every
// 40th grain killed (from the 8th) and as many born (*born of them) at the end
inline std::vector<size_t> blocks_reversed(size_t n) {
  std::vector<size_t> order;
  for (size_t b = 0; b < n; b += 64)
    for (size_t i = 0; i < 64 && b + i < n; ++i) order.push_back(n - 1 - b - i);
  return order;
}
inline std::vector<size_t> killed_and_born(size_t n, size_t* born) {
  std::vector<size_t> order;
  for (size_t i = 0; i < n; ++i)
    if (i % 40 != 7) order.push_back(i);
  for (*born = 0; order.size() < n; ++*born) order.push_back(n + *born);
  return order;
}

}  // namespace grains::test
