// The OpenCL backend (a grains node's use_opencl; nodes/grains/opencl/iterations.h), with
// either contact solver, on PoCL's CPU device, which scripts/install-deps.sh installs on every machine that runs the tests: the
// same results as the CPU path within float rounding where the motion is smooth, the same
// frames run to run, and a clear refusal where there is no device. Longer runs are checked by
// their physical measures beside the CPU path's tests (stacks, sand_pile, the DEM collapse:
// test names starting "use_opencl:", CTest label opencl).
#include <stdlib.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>

#include "nodes/grains/opencl/iterations.h"
#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/support.h"

using namespace grains;

namespace {

// sand_pile's first `frames` frames with `sets` and use_opencl as given
std::unique_ptr<Simulation> pour(bool opencl, int frames, std::vector<std::string> sets = {},
                                 int threads = 1) {
  register_builtin_nodes();
  sets.push_back(std::string("grains.use_opencl=") + (opencl ? "true" : "false"));
  std::vector<Override> overrides;
  for (const std::string& s : sets) overrides.push_back(parse_override(s));
  Graph g = load_graph(test::source_dir() + "/graphs/sand_pile.json", overrides);
  auto sim = std::make_unique<Simulation>(g, threads);
  for (int f = 0; f < frames; ++f) sim->step_frame();
  return sim;
}

std::vector<float> array(const Simulation& sim, const char* name) {
  const ParticleStore& pts = sim.object(0).pts;
  const float* a = pts.v3_if(name);
  return std::vector<float>(a, a + 3 * pts.size());
}

// runs `args` with the environment variable `var` set to `value` (unset after)
int run_with(const char* var, const std::string& value, const std::string& args,
             const std::string& log) {
  const char* before = getenv(var);
  const std::string saved = before ? before : "";
  setenv(var, value.c_str(), 1);
  const int rc = test::run_grains(args, log);
  if (before) setenv(var, saved.c_str(), 1);
  else unsetenv(var);
  return rc;
}

// a jittered 10 x 8 x 10 block of grains of radius r settled on the ground on the CPU (8 x 40,
// 0.5 s), with `settings` for the substep to come, friction off: a switch between sticking and
// sliding is a step, no bound on the backends' difference holds across it
test::Scene settled_block(float r, const GrainsSettings& settings) {
  test::Scene packed;
  packed.add_collider(test::ground());
  packed.add_jittered_block(10, 8, 10, r);
  packed.s = test::settings(24, 8, 40);  // settled with shallow overlaps
  packed.run(0.5f);
  packed.s = settings;
  packed.s.friction_with_particles = 0;
  packed.s.friction_with_colliders = 0;
  return packed;
}

// the premise of the bounds: how deep two grains can press into each other during the substep
// (the deepest overlap now, plus two grains' approach in one substep at the fastest speed and
// gravity's g dt^2), over the distance that leaves (`stretch`), and the coordinates' reach
struct Premise {
  double deepest = 0, fastest = 0, reach = 0, press = 0, stretch = 0;
};
Premise premise(const test::Scene& packed, float r) {
  Premise m;
  for (size_t i = 0; i < packed.size(); ++i) {
    m.fastest = std::max(m.fastest, double(length(packed.vel(i))));
    for (int a = 0; a < 3; ++a) m.reach = std::max(m.reach, std::fabs(double(packed.P[3 * i + a])));
    for (size_t j = i + 1; j < packed.size(); ++j)
      m.deepest = std::max(m.deepest, 2.0 * r - length(packed.pos(i) - packed.pos(j)));
  }
  const double dt = packed.s.dt;
  m.press = m.deepest + 2 * m.fastest * dt + test::kG * dt * dt;
  m.stretch = m.press / (2 * r - m.press);
  return m;
}

// one substep of `packed` on each backend: the largest distance between a grain's two
// positions, and the CPU's pairs closer than `touch`
struct Apart {
  double worst = 0;     // m
  size_t touching = 0;  // pairs
  int stabilize = 0;    // the CPU's pre-stabilization passes
};
Apart one_substep_apart(const test::Scene& packed, float touch) {
  test::Scene cpu = packed, dev = packed;
  dev.s.use_opencl = true;
  cpu.substep();
  dev.substep();
  Apart a;
  a.stabilize = cpu.solver.stabilize_passes();
  for (size_t i = 0; i < cpu.size(); ++i) {
    a.worst = std::max(a.worst, static_cast<double>(length(cpu.pos(i) - dev.pos(i))));
    for (size_t j = i + 1; j < cpu.size(); ++j) a.touching += length(cpu.pos(i) - cpu.pos(j)) < touch;
  }
  return a;
}

}  // namespace

TEST_CASE("use_opencl: a substep agrees with the CPU path's within float rounding", "[opencl]") {
  // A jittered 10 x 8 x 10 block of grains (r = 5 cm) settled on the ground on the CPU (8 x 40,
  // 0.5 s), then one more substep (2 x 20 at 24 fps, friction off) on each backend from that
  // same state. The host predicts and finds the collider planes alike; the device finds the
  // same neighbour rows, pre-stabilizes and iterates with the CPU's functions; the backends may
  // sum in another order or fuse a multiply and an add elsewhere, a few units in the last place
  // of a coordinate per pass: 4 x 2^-24 x the coordinates' reach (about 1 m). An averaged
  // Jacobi pass of contacts moves two nearby states apart by at most (1 + overlap / distance)
  // per pass, so after S passes (the I iterations and the CPU's pre-stabilization passes) the
  // two differ by at most S x 4 ulp x (1 + overlap / distance)^S, with the overlap grains can reach
  // in the substep measured from the settled state (about 1.3e-5 m, 3e-4 of a radius). The same
  // with the neighbour rows rebuilt before every iteration (there, within the one device call).
  // Over many substeps no such bound holds: a difference turns into velocity and grains that meet
  // scatter it like billiard balls (a frictionless pour parts by 7 mm within a frame once grains
  // land on grains), and with friction a contact's switch between sticking and sliding is a step;
  // the physical measures are compared instead (the other "use_opencl:" tests).
  const float r = 0.05f;
  GrainsSettings settings = test::settings(24, 2, 20);
  settings.contact_solver = kContactJacobi;
  test::Scene packed = settled_block(r, settings);
  const Premise m = premise(packed, r);
  INFO("deepest overlap " << m.deepest << " m, fastest " << m.fastest << " m/s: overlap / distance at most "
                          << m.stretch << "; coordinates within " << m.reach << " m");
  for (bool rebuild : {false, true}) {
    INFO((rebuild ? "rows rebuilt every iteration" : "rows once a substep"));
    packed.s.update_neighbors_during_iterations = rebuild;
    const Apart a = one_substep_apart(packed, 2 * r);
    const int S = packed.s.constraint_iterations + a.stabilize;
    const double bound = S * 4 * std::ldexp(m.reach, -24) * std::pow(1 + m.stretch, S);
    INFO("largest difference " << a.worst << " m; " << a.touching << " touching pairs; "
                               << a.stabilize << " pre-stabilization passes; bound " << bound << " m");
    CHECK(a.touching > 800);  // a packing, not a gas
    CHECK(a.worst <= bound);
  }
}

TEST_CASE("use_opencl: a gauss_seidel substep agrees with the CPU path's within float rounding",
          "[opencl][gauss_seidel]") {
  // The same settled block, one more substep of the contacts one at a time (8 x 10 at 24 fps,
  // the node's 10 passes; friction off: a switch between sticking and sliding is a step, no
  // bound holds across it).
  // The host builds the contacts alike; the device pre-stabilizes, warm-starts and runs the
  // passes, in the CPU's order (blocks in colours), with the same functions, which it may
  // compile with another fusing of multiplies and adds: a few units in the last place of a
  // coordinate a move, 4 x 2^-24 x the coordinates' reach. A pass moves a grain once for each
  // of its z contacts, each move projecting the pair's distance onto r_i + r_j, which stretches
  // a difference between two nearby states by at most (r_i + r_j) / |x_ij| = 1 + overlap /
  // distance; over S sweeps the two differ by at most z S x 4 ulp x (1 + stretch)^(z S), z the
  // most grains any grain can touch in the substep (counted) and the overlap the deepest the
  // substep can reach (as in the Jacobi test above; with the exponent z S, a substep of 2 x 20,
  // whose fall g dt^2 is 8.5% of a radius, would bound nothing). S: the I passes, the CPU's
  // pre-stabilization passes and the warm start's sweep that applies the loads.
  const float r = 0.05f;
  test::Scene packed = settled_block(r, test::settings(24, 8, 10));
  REQUIRE(packed.s.contact_solver == kContactGaussSeidel);
  const Premise m = premise(packed, r);
  int z = 1;  // the ground's plane counts as one more contact
  for (size_t i = 0; i < packed.size(); ++i) {
    int near = 1;
    for (size_t j = 0; j < packed.size(); ++j)
      near += j != i && length(packed.pos(i) - packed.pos(j)) < 2 * r + m.press;
    z = std::max(z, near);
  }
  INFO("deepest overlap " << m.deepest << " m, fastest " << m.fastest << " m/s: overlap / distance at most "
                          << m.stretch << "; at most " << z << " contacts a grain");
  // touching: within a thousandth of a diameter (rigid contacts end at 2 r, not inside it).
  // Both sweep orders: by lower index (one work-item a block, PoCL's), and in waves with 64
  // work-items a block (a GPU's), the CPU path then sweeping the waves too (sweep_waves)
  for (const bool waves : {false, true}) {
    test::ScopedEnv items("GRAINS_OPENCL_SWEEP_ITEMS", waves ? "64" : "1");
    packed.s.sweep_waves = waves;
    const Apart a = one_substep_apart(packed, 2.002f * r);
    const int S = packed.s.constraint_iterations + a.stabilize + 1;
    const double bound = z * S * 4 * std::ldexp(m.reach, -24) * std::pow(1 + m.stretch, z * S);
    INFO("waves " << waves << ": largest difference " << a.worst << " m; " << a.touching
                  << " touching pairs; " << a.stabilize << " pre-stabilization passes; bound "
                  << bound << " m");
    CHECK(a.touching > 800);  // a packing, not a gas
    CHECK(a.worst <= bound);
  }
}

TEST_CASE(
    "use_opencl: gauss_seidel's contacts split over device buffers, or a block's waves over "
    "work-items, give the same bits",
    "[opencl][gauss_seidel]") {
  // One device buffer holds at most CL_DEVICE_MAX_MEM_ALLOC_SIZE (PoCL: 4 GiB, 77 million
  // contacts of 56 bytes: ten million grains need more), so the contacts go to the device in
  // parts of whole blocks, each colour's blocks swept part by part. No two blocks of a colour
  // write one grain, so the parts give the bits one buffer gives. With several work-items a
  // block (GRAINS_OPENCL_SWEEP_ITEMS) the contacts come in waves and the items share each wave's
  // contacts (no two of a wave move one grain), which gives the bits of any other count of
  // items. A jittered block of 10,240 grains (ten blocks of 1,024) drops onto the ground for 12
  // substeps, with every part at most 1 MiB (GRAINS_OPENCL_MAX_BUFFER_MIB=1: 18,724 contacts)
  // and without the cap: one item a block (the order by lower index), and 7 and 64 items (the
  // waves). (PoCL runs a work-group's items one after another between barriers: this checks
  // which contacts each item takes and the barriers' places, not a GPU's lanes racing; the
  // waves' own test is "... a block's contacts come in waves that move no grain twice".)
  const float r = 0.01f;
  auto drop = [&](bool capped, const char* items) {
    std::unique_ptr<test::ScopedEnv> cap;
    if (capped) cap = std::make_unique<test::ScopedEnv>("GRAINS_OPENCL_MAX_BUFFER_MIB", "1");
    test::ScopedEnv sweep("GRAINS_OPENCL_SWEEP_ITEMS", items);
    test::Scene s;
    s.add_collider(test::ground());
    s.add_jittered_block(40, 16, 16, r);
    s.s = test::settings(24, 2, 10);
    s.s.use_opencl = true;
    for (int k = 0; k < 12; ++k) s.substep();
    return s;
  };
  const test::Scene whole = drop(false, "1"), waves = drop(false, "7");
  REQUIRE(whole.s.contact_solver == kContactGaussSeidel);
  // the premise: more contacts than one part holds (every touching pair is a contact)
  size_t touching = 0;
  for (size_t i = 0; i < whole.size(); ++i)
    for (size_t j = i + 1; j < whole.size(); ++j) touching += length(whole.pos(i) - whole.pos(j)) < 2.002f * r;
  INFO(touching << " touching pairs");
  REQUIRE(touching * sizeof(gr_seq_contact) > (size_t(1) << 20));
  for (const auto& [capped, items] :
       {std::pair{true, "1"}, {true, "7"}, {false, "64"}, {true, "64"}}) {
    INFO("parts of 1 MiB: " << capped << "; work-items a block: " << items);
    const test::Scene other = drop(capped, items),
                      &same = std::string(items) == "1" ? whole : waves;
    CHECK(same.P == other.P);
    CHECK(same.v == other.v);
  }
  // the two orders are two sweeps, not the same bits
  CHECK(whole.P != waves.P);
}

TEST_CASE("use_opencl: the contact list the device builds is the host's, loads and all",
          "[opencl][gauss_seidel]") {
  // With use_opencl, gauss_seidel's list is built on the device from the rows and planes it is
  // sent (gr_seq_build, the host's function), each contact's carried load found there by key in
  // the list the device's last solve left (Iterations::build_sequential), and the list stays
  // there: neither it nor its loads cross each substep. GRAINS_OPENCL_HOST_CONTACTS=1 has the
  // host build the list and look the loads up, as the CPU path does, and send it. Both ways,
  // test::layered_drop (512 grains falling onto the ground at 8 x 10, 96 substeps, lists kept
  // and rebuilt): the same list, field for field, the same loads and the same bits; with a
  // work-item a block, and with 64, whose list comes in waves, ordered on the device too.
  for (const char* items : {"1", "64"}) {
    INFO("work-items a block: " << items);
    test::ScopedEnv sweep("GRAINS_OPENCL_SWEEP_ITEMS", items);
    size_t kept_there = 0, kept_here = 0;
    const test::Scene there = test::layered_drop(true, false, &kept_there);
    const test::Scene here = [&] {
      test::ScopedEnv host("GRAINS_OPENCL_HOST_CONTACTS", "1");
      return test::layered_drop(true, false, &kept_here);
    }();
    INFO("lists built on the device: " << there.solver.contact_lists_built_on_device()
                                       << "; kept: " << kept_there << " and " << kept_here);
    REQUIRE(there.solver.contact_lists_built_on_device() >= 10);  // the premise: warm rebuilds
    CHECK(here.solver.contact_lists_built_on_device() == 0);
    CHECK(kept_there == kept_here);
    const std::vector<gr_seq_contact>& a = there.solver.contact_list();
    const std::vector<gr_seq_contact>& b = here.solver.contact_list();
    REQUIRE(a.size() == b.size());
    REQUIRE(a.size() > 512);
    size_t differ = 0, loaded = 0;
    auto same = [](float x, float y) { return std::memcmp(&x, &y, sizeof x) == 0; };
    for (size_t k = 0; k < a.size(); ++k) {
      const gr_seq_contact &x = a[k], &y = b[k];
      const bool equal = x.i == y.i && x.j == y.j && x.e == y.e && x.moves == y.moves &&
                         x.key == y.key && same(x.k, y.k) && same(x.share, y.share) &&
                         same(x.mu, y.mu) && same(x.ln, y.ln) && same(x.lt[0], y.lt[0]) &&
                         same(x.lt[1], y.lt[1]) && same(x.lt[2], y.lt[2]);
      differ += !equal;
      loaded += x.ln > 0.0f;
    }
    INFO(a.size() << " contacts, " << loaded << " loaded");
    CHECK(differ == 0);
    CHECK(loaded > 256);
    CHECK(there.P == here.P);
    CHECK(there.v == here.v);
  }
  // across frames, whose grains the node sorts again each frame (a load is found by the grains'
  // ids): sand_pile, 6 frames
  auto built = pour(true, 6);
  auto sent = [&] {
    test::ScopedEnv host("GRAINS_OPENCL_HOST_CONTACTS", "1");
    return pour(true, 6);
  }();
  CHECK(array(*built, "P") == array(*sent, "P"));
  CHECK(array(*built, "v") == array(*sent, "v"));
}

TEST_CASE(
    "use_opencl: the neighbour rows stay on the device, and the host's reads of them are "
    "made there",
    "[opencl][gauss_seidel]") {
  // When the device builds gauss_seidel's list from its own rows, nothing else in the substep
  // reads the rows on the host: their indices stay on the device, and error control's overlap
  // statistics (contact_stats) and the Verlet skin (remember_rows) are reduced there, run by
  // run (kernels/row_stats.h). test::layered_drop measures the statistics after each of its 96
  // substeps; with GRAINS_OPENCL_HOST_CONTACTS=1 the host builds the list, so the rows come back
  // and the host measures. The skin decides when the rows are kept: the same frames, bit for
  // bit, and the same lists kept, say the device's skin is the host's.
  size_t kept_there = 0, kept_here = 0;
  const test::Scene there = test::layered_drop(true, false, &kept_there);
  const test::Scene here = [&] {
    test::ScopedEnv host("GRAINS_OPENCL_HOST_CONTACTS", "1");
    return test::layered_drop(true, false, &kept_here);
  }();
  INFO("searches whose rows stayed on the device: " << there.solver.rows_left_on_device());
  CHECK(there.solver.rows_left_on_device() >= 10);
  CHECK(here.solver.rows_left_on_device() == 0);
  CHECK(kept_there == kept_here);
  REQUIRE(there.P == here.P);
  CHECK(there.v == here.v);
  // The statistics of the same positions: a pair's overlap / summed radii is
  // (r_i + r_j - |x_ij|) / (r_i + r_j), whose rounding is a few ulp of the summed radii over
  // them, 4 x 2^-23 < 1e-6, however the two compilers order or fuse the length's arithmetic;
  // only pairs touching within that may count on one side alone (counted here, every pair).
  size_t edge = 0;
  for (size_t i = 0; i < here.size(); ++i)
    for (size_t j = i + 1; j < here.size(); ++j) {
      const float rsum = here.pscale[i] + here.pscale[j];
      edge += std::fabs(rsum - length(here.pos(i) - here.pos(j))) / rsum < 1e-6f;
    }
  const GrainsStats &a = there.stats, &b = here.stats;
  INFO("touching pairs " << a.contacts << " and " << b.contacts << " (" << edge
                         << " within rounding of touching); largest overlap " << a.max_penetration
                         << " and " << b.max_penetration << "; mean " << a.mean_penetration
                         << " and " << b.mean_penetration);
  REQUIRE(b.contacts > 256);  // the premise: hundreds of pairs, most grains landed
  CHECK(std::abs(double(a.contacts) - double(b.contacts)) <= double(edge));
  CHECK(std::fabs(a.max_penetration - b.max_penetration) <= 1e-6f);
  CHECK(std::fabs(a.mean_penetration - b.mean_penetration) <= 1e-6f);
  CHECK(a.mean_penetration > 0.0f);
  // rows cut at max_neighbors, whose skin is the cut rows' reach: the same lists kept and the
  // same frames (the premise: the cut shortens the skin, so fewer lists are kept than uncut)
  size_t cut_there = 0, cut_here = 0;
  const test::Scene cut = test::layered_drop(true, false, &cut_there, 4);
  const test::Scene cut_host = [&] {
    test::ScopedEnv host("GRAINS_OPENCL_HOST_CONTACTS", "1");
    return test::layered_drop(true, false, &cut_here, 4);
  }();
  INFO("lists kept with rows cut at 4: " << cut_there << " and " << cut_here << "; uncut "
                                         << kept_there);
  REQUIRE(cut_here < kept_here);
  CHECK(cut.solver.rows_left_on_device() >= 10);
  CHECK(cut_there == cut_here);
  CHECK(cut.P == cut_host.P);
  CHECK(cut.v == cut_host.v);
  // grains of no size: the device's search returns empty rows at once, and the statistics and
  // the rows the host reads after are of no pairs (not a fetch from a search that made none)
  test::Scene points;
  points.s = test::settings(24, 8, 10);
  points.s.contact_solver = kContactGaussSeidel;
  points.s.use_opencl = true;
  points.add_collider(test::ground());
  for (int k = 0; k < 8; ++k) points.add({0.1f * k, 0.5f, 0.0f}, 0.0f);
  points.substep();
  points.substep();
  CHECK(points.stats.contacts == 0);
  REQUIRE(points.solver.candidates());
  CHECK(points.solver.candidates()->indices.empty());
}

TEST_CASE(
    "use_opencl: with rigid shapes the device's gauss_seidel passes give the grains outside them "
    "the bits they give without",
    "[opencl][gauss_seidel][shape]") {
  // With rigid shape matching the device projects the shapes after each pass (gr_k_shapes, a
  // work-group a component, which writes only the components' grains), within the solve that
  // runs the passes without shapes too. For grains in no shape the two are the same operations
  // on the same values: the same bits. The settled block squeezed
  // to 97% of its height (overlaps of about 0.06 r between layers, which pre-stabilization
  // removes from the start), with friction on (friction reads the start: a grain's slip is
  // measured from it), one substep, once with a rigid pair far above it (connected, so that
  // shapes are on; in the air, touching nothing) and once with the same pair but shape
  // matching off.
  const float r = 0.05f;
  test::Scene packed = settled_block(r, test::settings(24, 8, 10));
  for (size_t i = 0; i < packed.size(); ++i) packed.P[3 * i + 1] *= 0.97f;
  packed.s.friction_with_particles = 1;
  packed.s.friction_with_colliders = 1;
  REQUIRE(packed.s.contact_solver == kContactGaussSeidel);
  REQUIRE(packed.s.pre_stabilization);
  const size_t block = packed.size();
  packed.connect(packed.add({0, 5, 0}, r), packed.add({2 * r, 5, 0}, r));
  packed.s.explicit_constraints_weight = 0;  // the pair's primitive is shape matching's only
  packed.s.use_opencl = true;
  test::Scene shaped = packed, plain = packed;
  shaped.s.enable_rigid_shape_matching = true;
  plain.s.enable_rigid_shape_matching = false;
  shaped.substep();
  plain.substep();
  // the premise: pre-stabilization moved the block (else its start is the substep's)
  INFO(shaped.solver.stabilize_passes() << " pre-stabilization passes");
  CHECK(shaped.solver.stabilize_passes() > 1);
  auto same = [](const Vec3& a, const Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; };
  size_t differ = 0;
  for (size_t i = 0; i < block; ++i)
    differ += !same(shaped.pos(i), plain.pos(i)) || !same(shaped.vel(i), plain.vel(i));
  CHECK(differ == 0);
  // and the pair kept its length (its shape held), to a few units in the last place of its
  // coordinates (5 m up: 2^-21 m)
  CHECK(length(shaped.pos(block) - shaped.pos(block + 1)) ==
        Approx(2 * r).margin(4 * std::ldexp(1.0, -21)));
}

TEST_CASE("use_opencl: a contact list kept on the device gives what rebuilding it gives",
          "[opencl][gauss_seidel]") {
  // While gauss_seidel keeps its contact list across substeps (the CPU path's test "... a contact
  // list kept across substeps gives what rebuilding it gives"), the list the device's last call
  // left there stays on the device: it is not uploaded again, and each contact's load is kept
  // there (gr_k_keep, the host's gr_seq_keep). A state written and read back between substeps
  // drops the list, so that run builds and uploads it every substep: both must give the same
  // bits (test::layered_drop: 512 grains fall onto the ground at 8 x 10).
  size_t kept = 0, rebuilt = 0;
  const test::Scene a = test::layered_drop(true, false, &kept),
                    b = test::layered_drop(true, true, &rebuilt);
  REQUIRE(a.s.contact_solver == kContactGaussSeidel);
  INFO("substeps that kept the list: " << kept << " of 96 (round trip: " << rebuilt << ")");
  CHECK(kept >= 48);
  CHECK(rebuilt == 0);
  CHECK(a.P == b.P);
  CHECK(a.v == b.v);
}

TEST_CASE(
    "use_opencl: a copy or a move of a solver whose list the device keeps runs on as the original",
    "[opencl][gauss_seidel]") {
  // A copy of the solver opens a device of its own, which holds none of the contacts the
  // original's device keeps: the copy must upload its list, not take the empty device's. The
  // contact-list scene is copied after its 96 substeps (the last ones kept their list) and both
  // run 24 more.
  // A move brings the host's copy of the list from the device before the device moves with it
  // (the list stays on the device after each solve): a scene moved while its list is there
  // runs on as the original too.
  size_t kept = 0;
  test::Scene a = test::layered_drop(true, false, &kept);
  test::Scene b = a;
  test::Scene there = test::layered_drop(true, false, &kept);
  test::Scene moved = std::move(there);
  const size_t before = a.solver.contact_lists_kept();
  for (int k = 0; k < 24; ++k) a.substep(), b.substep(), moved.substep();
  INFO("lists kept in the 24 substeps: " << a.solver.contact_lists_kept() - before);
  REQUIRE(a.solver.contact_lists_kept() > before);  // the premise: the copy ran on a kept list
  CHECK(a.P == b.P);
  CHECK(a.v == b.v);
  CHECK(a.P == moved.P);
  CHECK(a.v == moved.v);
}

TEST_CASE("use_opencl: a substep that needs a buffer larger than the device's largest is refused",
          "[opencl][bad]") {
  // A driver need not refuse a buffer over its CL_DEVICE_MAX_MEM_ALLOC_SIZE (PoCL 3.1 took one of
  // 4.9 GB with a 4 GiB limit and crashed copying into it): Grains checks. 98,304 grains' positions
  // are 1.1 MiB, over a cap of 1 MiB.
  test::ScopedEnv cap("GRAINS_OPENCL_MAX_BUFFER_MIB", "1");
  test::Scene s;
  s.add_collider(test::ground());
  s.add_jittered_block(96, 32, 32, 0.01f);
  s.s = test::settings(24, 1, 1);
  s.s.use_opencl = true;
  CHECK_THROWS_WITH(s.substep(), Catch::Contains("more than the device's largest, 1.0 MiB") &&
                                     Catch::Contains("run them on the CPU (use_opencl off)"));
}

TEST_CASE("use_opencl: the same graph gives the same frames run to run", "[opencl]") {
  // A Jacobi work-item writes only its own grain's outputs and sums its contacts in row order;
  // a Gauss-Seidel work-group sweeps one block of contacts wave by wave, and no two blocks swept
  // at once, nor two contacts of a wave, write one grain: the device's result does not depend on
  // how it schedules them, and the host's part of the substep is the CPU path's, the same for any
  // thread count. sand_pile with friction, 6 frames, with one host thread and with two: the same
  // bits, on both solvers, and with jacobi's rows and planes found again every iteration (the
  // carry kernels copy by neighbour and by collider, each work-item its own grain's).
  const std::vector<std::vector<std::string>> variants = {
      {"grains.contact_solver=gauss_seidel"},
      {"grains.contact_solver=jacobi"},
      {"grains.contact_solver=jacobi", "grains.update_neighbors_during_iterations=1",
       "grains.update_collisions_during_iterations=1"}};
  for (const std::vector<std::string>& sets : variants) {
    INFO(sets.back());
    auto one = pour(true, 6, sets, 1), two = pour(true, 6, sets, 2);
    CHECK(array(*one, "P") == array(*two, "P"));
    CHECK(array(*one, "v") == array(*two, "v"));
  }
}

TEST_CASE("use_opencl on a device without double precision: the host's stages, the same frames",
          "[opencl][mesh][shape]") {
  // A device without cl_khr_fp64 has none of the kernels that need doubles (the neighbour rows,
  // rigid shapes, mesh queries, the sleeping test, the motion measure: kernels/prelude.h,
  // GR_DOUBLES); the host makes those stages with the same functions. GRAINS_OPENCL_NO_FP64=1
  // builds PoCL's program as for such a device: the solver finds none of them there, and
  // mesh_bowl (a mesh collider, sleeping, error control) and rigid_rocks (rigid shapes, jacobi's
  // clumping) write the same frames, bit for bit, as with them there. Before 2026-12-05 such a
  // program did not build at all (kernels/row_stats.h).
  register_builtin_nodes();
  {
    test::ScopedEnv no("GRAINS_OPENCL_NO_FP64", "1");
    opencl::Iterations device;
    CHECK(!device.shapes_there());
    CHECK(!device.meshes_there());
    CHECK(!device.sleeps_there());
  }
  {
    opencl::Iterations device;  // the premise: PoCL's device has them
    REQUIRE(device.meshes_there());
    REQUIRE(device.sleeps_there());
  }
  for (const char* name : {"mesh_bowl", "rigid_rocks"}) {
    INFO(name);
    auto frames = [&](bool doubles) {
      test::ScopedEnv no("GRAINS_OPENCL_NO_FP64", doubles ? "0" : "1");
      Graph g = load_graph(test::source_dir() + "/graphs/" + name + ".json",
                           {parse_override("grains.use_opencl=true")});
      Simulation sim(g, 1);
      std::vector<std::vector<float>> out;
      for (int f = 0; f < 24; ++f) {
        sim.step_frame();
        out.push_back(array(sim, "P"));
        out.push_back(array(sim, "v"));
      }
      return out;
    };
    const auto with = frames(true), without = frames(false);
    REQUIRE(with.size() == without.size());
    for (size_t k = 0; k < with.size(); ++k) {
      INFO((k % 2 ? "v" : "P") << " of frame " << k / 2 + 1);
      CHECK(with[k] == without[k]);
    }
  }
}

TEST_CASE("grains run --opencl runs every grains node on the device", "[cli][opencl]") {
  // --opencl is use_opencl on every grains node: its frames are byte for byte those of the
  // `--set` (the device is deterministic run to run, see above; the CPU path's frame_0002
  // differs from them, checked below, so a flag that did nothing would fail)
  const std::string dir = test::temp_dir("run_opencl");
  const std::string graph = test::source_dir() + "/graphs/sand_pile.json";
  const std::string run = "run " + graph + " --frames 2 --quiet --out " + dir;
  REQUIRE(test::run_grains(run + "/flag --opencl", dir + "/log.txt") == 0);
  REQUIRE(test::run_grains(run + "/set --set grains.use_opencl=true", dir + "/log.txt") == 0);
  REQUIRE(test::run_grains(run + "/cpu", dir + "/log.txt") == 0);
  const std::string flag = test::read_text(dir + "/flag/frame_0002.ply");
  CHECK(flag.size() > 99 * 3 * sizeof(float));
  CHECK(flag == test::read_text(dir + "/set/frame_0002.ply"));
  CHECK(flag != test::read_text(dir + "/cpu/frame_0002.ply"));
}

TEST_CASE("use_opencl without an OpenCL platform, or with a device that is not there, exits 2",
          "[cli][opencl][bad]") {
  const std::string dir = test::temp_dir("opencl_no_device");
  std::filesystem::create_directories(dir + "/vendors");
  const std::string run = "run " + test::source_dir() + "/graphs/sand_pile.json --frames 1 --opencl --out " +
                          dir + "/o --overwrite";
  const std::string log = dir + "/log.txt";
  // the ICD loader reads its drivers from OCL_ICD_VENDORS: an empty folder is a machine without
  CHECK(run_with("OCL_ICD_VENDORS", dir + "/vendors", run, log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("/nodes/2/params/use_opencl: no OpenCL platform found"));
  CHECK(run_with("GRAINS_OPENCL_DEVICE", "0:7", run, log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("GRAINS_OPENCL_DEVICE: no device 0:7"));
  CHECK(run_with("GRAINS_OPENCL_DEVICE", "any", run, log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("GRAINS_OPENCL_DEVICE: 'any' is not PLATFORM:DEVICE"));
  CHECK(run_with("GRAINS_OPENCL_MAX_BUFFER_MIB", "4GiB", run, log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("/nodes/2/params/use_opencl: GRAINS_OPENCL_MAX_BUFFER_MIB: '4GiB' is "
                                                   "not a whole number of MiB"));
  CHECK(run_with("GRAINS_OPENCL_SWEEP_ITEMS", "2048", run, log) == 2);
  CHECK_THAT(test::read_text(log),
             Catch::Contains("/nodes/2/params/use_opencl: GRAINS_OPENCL_SWEEP_ITEMS: '2048' is "
                             "not a whole number from 1 to 1024"));
  CHECK(run_with("GRAINS_OPENCL_HOST_CONTACTS", "yes", run, log) == 2);
  CHECK_THAT(test::read_text(log),
             Catch::Contains("/nodes/2/params/use_opencl: GRAINS_OPENCL_HOST_CONTACTS: 'yes' is "
                             "neither 0 nor 1"));
  CHECK(run_with("GRAINS_OPENCL_HOST_SLEEP", "2", run, log) == 2);
  CHECK_THAT(test::read_text(log),
             Catch::Contains("/nodes/2/params/use_opencl: GRAINS_OPENCL_HOST_SLEEP: '2' is "
                             "neither 0 nor 1"));
  CHECK(run_with("GRAINS_OPENCL_NO_FP64", "true", run, log) == 2);
  CHECK_THAT(test::read_text(log),
             Catch::Contains("/nodes/2/params/use_opencl: GRAINS_OPENCL_NO_FP64: 'true' is "
                             "neither 0 nor 1"));
}
