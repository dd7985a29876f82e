// solver: one particle object. The evaluator runs its chain every substep; then this node moves
// every point whose `ispbd` is 0 and leaves the points a grains node moved (ispbd 1) alone.
//
// Integration is exact for a force constant over the substep: P += v dt + a dt^2 / 2,
// v += a dt, with a = force / mass (symplectic Euler would be off by a dt T / 2 after a fall of
// T seconds: 4% of the fall at 24 fps). A swept test finds the first contact with each collider
// along the substep; the point's velocity at that moment is reflected with the collider's bounce
// and slowed tangentially by Coulomb friction, relative to the collider's surface velocity, and
// the rest of the substep continues from the contact.
#include <omp.h>

#include <algorithm>
#include <cmath>

#include "engine/node.h"
#include "engine/simulation.h"
#include "nodes/register.h"

namespace grains {
namespace {

// Response of a point with velocity v touching collider c at P with outward normal n; `a` is
// its acceleration. Contacts slower than two substeps of that acceleration do not bounce, so a
// resting point does not jitter (Mueller et al. 2020, restitution threshold 2|g|h).
Vec3 respond(const ColliderState& c, const Vec3& P, const Vec3& v, const Vec3& n, const Vec3& a,
             float dt) {
  Vec3 vc = c.velocity_at(P);
  Vec3 vr = v - vc;
  float vn = dot(vr, n);
  if (vn >= 0) return v;
  float bounce = -vn > 2 * length(a) * dt ? c.bounce : 0.0f;
  Vec3 vt = vr - n * vn;
  float vt_len = length(vt);
  // Coulomb: the tangential speed drops by friction times the normal speed change
  float dvn = (1 + bounce) * -vn;
  float keep = vt_len > 0 ? std::max(0.0f, 1 - c.friction * dvn / vt_len) : 0.0f;
  return vc + n * (-bounce * vn) + vt * keep;
}

class SolverNode : public Node {
 public:
  void cook(CookContext& ctx) override {
    ParticleStore& s = ctx.pts;
    size_t n = s.size();
    float dt = static_cast<float>(ctx.time.dt);
    float* age = s.f("age");
    const int32_t* pbd = s.i("ispbd");
    for (size_t k = 0; k < n; ++k) age[k] += dt;
    // only the points no grains node moved are read: a grains node's may stay held where it
    // left them (particles.h)
    if (std::all_of(pbd, pbd + n, [](int32_t b) { return b != 0; })) return;
    float* P = s.v3("P");
    float* v = s.v3("v");
    const float* F = s.v3("force");
    const float* m = s.f("mass");
    const float* r = s.f("pscale");
    const std::vector<ColliderState>& cols = ctx.colliders;
#pragma omp parallel for schedule(static)
    for (long long kk = 0; kk < static_cast<long long>(n); ++kk) {
      size_t k = static_cast<size_t>(kk);
      if (pbd[k]) continue;
      Vec3 x0 = load3(P, k);
      Vec3 v0 = load3(v, k);
      // mass 0 is an anchor (inverse mass 0, docs/design-notes.md): forces do not move it
      Vec3 a = m[k] > 0 ? load3(F, k) / m[k] : Vec3{};
      Vec3 x1 = x0 + v0 * dt + a * (0.5f * dt * dt);
      Vec3 vk = v0 + a * dt;
      for (const ColliderState& c : cols) {
        float t = c.sweep(x0, x1, r[k]);
        if (t > 1) continue;
        // the contact point: carried with the collider's normal motion to its end pose (a moving
        // wall pushes), not its tangential motion (friction decides that), then pushed out
        float th = t * dt, rest = dt - th;
        Vec3 hit = x0 + v0 * th + a * (0.5f * th * th);
        Vec3 carried = c.pose.apply(c.prev_pose.inverse(hit));
        Vec3 nrm;
        c.distance(carried, &nrm);
        Vec3 slip = hit - carried;
        carried += slip - nrm * dot(slip, nrm);
        float d = c.distance(carried, &nrm);
        Vec3 xc = carried + nrm * (r[k] - d);
        Vec3 vc = respond(c, xc, v0 + a * th, nrm, a, dt);
        // the rest of the substep from the contact; never back into the collider
        x1 = xc + vc * rest + a * (0.5f * rest * rest);
        vk = vc + a * rest;
        float d1 = c.distance(x1, &nrm);
        if (d1 < r[k]) {
          // resting contact: the normal velocity the rest of the substep gained is removed,
          // with its Coulomb friction (too slow to bounce)
          x1 += nrm * (r[k] - d1);
          vk = respond(c, x1, vk, nrm, a, dt);
        }
      }
      store3(P, k, x1);
      store3(v, k, vk);
    }
  }
};

}  // namespace

void register_solver_node() {
  NodeTypeInfo t;
  t.type = "solver";
  t.doc = "Ends a chain: one particle object; runs its chain each substep and moves non-grains points.";
  t.role = NodeRole::Solver;
  t.params = SolverParams::decls();  // engine/simulation.h: the evaluator reads them
  t.make = [] { return std::make_unique<SolverNode>(); };
  register_node_type(std::move(t));
}

}  // namespace grains
