// The grains node's sleeping test reads the neighbour rows where they are: on the OpenCL device
// while they stay there (GrainsSolver::sleep_rows_on_device, kernels/row_stats.h), so that the
// rows' indices (4 bytes a candidate) do not come back for it.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>

#include "nodes/grains/kernels/row_stats.h"
#include "nodes/grains/sleep_rows.h"
#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/support.h"

using namespace grains;

TEST_CASE(
    "use_opencl: the sleeping test's reads along the rows, made on the device, are the host's",
    "[opencl][sleeping]") {
  // The contact-list scene (512 grains settled on the ground at 8 x 10, the rows left on the
  // device) and one more substep: each grain's word from the device (its neighbours within 1.05
  // and 1.25 summed radii, and whether one flagged fast lies within 1.05), at the positions the
  // substep wrote (which the device holds from error control's statistics) and at positions
  // moved from them (sent), against the host's counts along the same rows, bit for bit.
  size_t kept = 0;
  test::Scene sc = test::layered_drop(true, false, &kept);
  sc.substep();
  const size_t n = sc.size();
  std::vector<uint8_t> fast(n);
  for (size_t j = 0; j < n; ++j) fast[j] = j % 3 == 0;
  std::vector<float> moved = sc.P;
  for (size_t k = 0; k < n; k += 5) moved[3 * k] += 0.3f * sc.pscale[k];
  std::vector<uint32_t> written, shifted;
  // the moved positions first: they replace the written ones on the device, which must then be
  // sent again
  REQUIRE(sc.solver.sleep_rows_on_device(moved.data(), true, fast.data(), &shifted));
  REQUIRE(sc.solver.sleep_rows_on_device(sc.P.data(), false, fast.data(), &written));
  CHECK(sc.solver.sleep_rows_device() == 2);
  const NeighborList& rows = *sc.solver.candidates();  // brings the rows to the host
  // once the host holds them, the counts are its own
  std::vector<uint32_t> none;
  CHECK_FALSE(sc.solver.sleep_rows_on_device(sc.P.data(), false, fast.data(), &none));
  for (const auto& [P, words] : {std::pair{&sc.P, &written}, std::pair{&moved, &shifted}}) {
    size_t differ = 0, touching = 0, woken = 0;
    for (size_t k = 0; k < n; ++k) {
      const uint32_t w = (*words)[k];
      const uint32_t near = sleep_row_near(rows, P->data(), sc.pscale.data(), k, GR_SLEEP_NEAR);
      const uint32_t kept_near =
          sleep_row_near(rows, P->data(), sc.pscale.data(), k, GR_SLEEP_KEPT);
      const bool fast_near =
          sleep_row_fast_near(rows, P->data(), sc.pscale.data(), fast.data(), k, GR_SLEEP_NEAR);
      differ += (w & GR_SLEEP_COUNT_MAX) != near || ((w >> 15) & GR_SLEEP_COUNT_MAX) != kept_near ||
                ((w & GR_SLEEP_FAST) != 0) != fast_near || (w & GR_SLEEP_OVER) != 0;
      touching += near;
      woken += fast_near;
    }
    INFO(touching << " neighbours within 1.05 summed radii, " << woken
                  << " grains near a fast one");
    CHECK(differ == 0);
    // the premise: the grains touch, and the fast flags split them
    CHECK(touching > n);
    CHECK(woken > 0);
    CHECK(woken < n);
  }
}

TEST_CASE("use_opencl: the sleeping test's counts agree with the host's at near ties",
          "[opencl][sleeping]") {
  // Bit for bit, not only where no distance lies near a threshold: 1,600 pairs of grains of 1 cm,
  // a pair 8 radii from the next, each pair's grains 1.05 or 1.25 summed radii apart in a
  // direction of their own (the exact distance rounded to float coordinates), so that the
  // distance's last bits decide about half of the counts. A device that fused a multiply and an
  // add there (FP_CONTRACT on in kernels/row_stats.h), or a host that did, counts some of them
  // otherwise. One substep finds the rows (the pairs in mid-air touch nothing), then both count
  // at the tie positions. The rows reach 5 summed radii, to the neighbouring pairs: rows of the
  // partner alone would take less to bring than the tie positions take to send, and come back
  // for the count (GrainsSolver::read_rows).
  const float r = 0.01f;
  test::Scene sc;
  sc.s = test::settings(24, 8, 10);
  sc.s.contact_solver = kContactGaussSeidel;
  sc.s.use_opencl = true;
  sc.s.neighbor_query_scale = 5;
  // the tie positions: each pair's first grain on a coarse grid (its differences exact), the
  // second at the exact distance from it in a direction of its own, rounded
  test::Sequence seq;
  std::vector<float> P;
  for (int a = 0; a < 40; ++a)
    for (int b = 0; b < 40; ++b) {
      const double reach = (a + b) % 2 ? GR_SLEEP_NEAR : GR_SLEEP_KEPT;
      const double theta = 6.283185307179586 * seq.next(), z = 2.0 * seq.next() - 1.0;
      const double s = std::sqrt(1.0 - z * z), L = reach * (2.0 * double(r));
      const float c[3] = {8 * r * a, 1.0f, 8 * r * b};
      const double d[3] = {L * s * std::cos(theta), L * z, L * s * std::sin(theta)};
      for (int x = 0; x < 3; ++x) P.push_back(c[x]);
      for (int x = 0; x < 3; ++x) P.push_back(static_cast<float>(c[x] + d[x]));
    }
  const size_t n = P.size() / 3;
  for (size_t k = 0; k < n; ++k) sc.add({P[3 * k], P[3 * k + 1], P[3 * k + 2]}, r);
  sc.substep();
  const std::vector<uint8_t> fast(n, 1);
  std::vector<uint32_t> words;
  REQUIRE(sc.solver.sleep_rows_on_device(P.data(), true, fast.data(), &words));
  const NeighborList& rows = *sc.solver.candidates();
  size_t differ = 0, within = 0, partners = 0;
  for (size_t k = 0; k < n; ++k) {
    const uint32_t near = sleep_row_near(rows, P.data(), sc.pscale.data(), k, GR_SLEEP_NEAR);
    const uint32_t kept = sleep_row_near(rows, P.data(), sc.pscale.data(), k, GR_SLEEP_KEPT);
    const bool fast_near =
        sleep_row_fast_near(rows, P.data(), sc.pscale.data(), fast.data(), k, GR_SLEEP_NEAR);
    differ += (words[k] & GR_SLEEP_COUNT_MAX) != near ||
              ((words[k] >> 15) & GR_SLEEP_COUNT_MAX) != kept ||
              ((words[k] & GR_SLEEP_FAST) != 0) != fast_near;
    for (uint32_t e = rows.offsets[k]; e < rows.offsets[k + 1]; ++e)
      partners += rows.indices[e] == (k ^ 1);
    within += near + kept;
  }
  // each grain of a pair 1.05 apart lies within 1.25 of its partner (n / 2 counts); the other
  // count of each grain is a tie
  const size_t ties_within = within - n / 2;
  INFO(rows.indices.size() << " row entries, " << ties_within << " of " << n
                           << " ties counted within");
  CHECK(differ == 0);
  // the premise: each grain's row holds its partner, and the ties fall both ways
  CHECK(partners == n);
  CHECK(rows.indices.size() > 3 * n);
  CHECK(ties_within > n / 5);
  CHECK(ties_within < 4 * n / 5);
}

TEST_CASE("use_opencl: sleeping grains give the same frames with the rows left on the device",
          "[opencl][sleeping]") {
  // sand_pile on the device for 36 frames with the host's sleeping test
  // (GRAINS_OPENCL_HOST_SLEEP=1): it reads the rows on the device while they stay there; with
  // GRAINS_OPENCL_HOST_CONTACTS=1 the host builds the contact list (the same list: "use_opencl:
  // the contact list the device builds is the host's"), the rows come back and the host counts
  // along them. The same bits, with grains asleep.
  test::ScopedEnv host_sleep("GRAINS_OPENCL_HOST_SLEEP", "1");
  auto run = [] {
    register_builtin_nodes();
    std::vector<Override> overrides{parse_override("grains.use_opencl=true")};
    Graph g = load_graph(test::source_dir() + "/graphs/sand_pile.json", overrides);
    auto sim = std::make_unique<Simulation>(g, 1);
    for (int f = 0; f < 36; ++f) sim->step_frame();
    return sim;
  };
  auto there = run();
  auto here = [&] {
    test::ScopedEnv host("GRAINS_OPENCL_HOST_CONTACTS", "1");
    return run();
  }();
  const ParticleStore &a = there->object(0).pts, &b = here->object(0).pts;
  REQUIRE(a.size() == b.size());
  size_t asleep = 0;
  const float* T = a.f_if("sleeptime");
  REQUIRE(T);
  for (size_t k = 0; k < a.size(); ++k) asleep += T[k] >= 0.5f;
  INFO(asleep << " of " << a.size() << " grains asleep");
  CHECK(asleep > 100);
  CHECK(std::memcmp(a.v3_if("P"), b.v3_if("P"), 3 * a.size() * sizeof(float)) == 0);
  CHECK(std::memcmp(a.v3_if("v"), b.v3_if("v"), 3 * a.size() * sizeof(float)) == 0);
  CHECK(std::memcmp(T, b.f_if("sleeptime"), a.size() * sizeof(float)) == 0);
}
