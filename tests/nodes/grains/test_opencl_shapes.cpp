// Rigid shape matching's shared functions (kernels/shapes.h): the rotation of the fit, and the
// projection the host makes (shapes.cpp) against the one an OpenCL device makes (gr_k_shapes),
// on PoCL's CPU device: both in double precision, without fused multiply-adds, the device's
// work-items of a component folding their sums in the host's order, so the same floats, bit for
// bit. And with the shapes on the device a substep's passes stay there: nothing of them crosses.
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <random>
#include <vector>

#include "nodes/grains/kernels/shapes.h"
#include "nodes/grains/opencl/iterations.h"
#include "nodes/grains/shapes.h"
#include "tests/nodes/grains/grains_harness.h"
#include "tests/support/cloud.h"

using namespace grains;
using test::unit;

namespace {

using M3 = Eigen::Matrix3d;

M3 random_rotation(std::mt19937& rng) {
  Eigen::Vector3d axis(unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5);
  return Eigen::AngleAxisd(6.0 * unit(rng), axis.normalized()).toRotationMatrix();
}

// the rotation the fit takes from A, by the shared function
M3 rotation_of(const M3& A) {
  double a[9], r[9];
  for (int k = 0; k < 9; ++k) a[k] = A(k / 3, k % 3);
  gr_shape_rotation(a, r);
  M3 R;
  for (int k = 0; k < 9; ++k) R(k / 3, k % 3) = r[k];
  return R;
}

// the reference: Eigen's SVD A = U D V^T, R = U V^T with the column of U of the smallest
// singular value turned where U V^T would be a reflection
M3 reference(const M3& A) {
  Eigen::JacobiSVD<M3> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
  M3 U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) = -U.col(2);
  return U * svd.matrixV().transpose();
}

// test::connected_cube, its lowest grain about 10 cm above the ground, shape matching and
// collider friction on, 8 x 10 at 24 fps
test::Scene tilted_cube() {
  test::Scene sc = test::connected_cube(0.1f);
  sc.s = test::settings(24, 8, 10);
  sc.s.explicit_constraints_weight = 0;
  sc.s.enable_rigid_shape_matching = true;
  sc.s.friction_with_colliders = 1;
  return sc;
}

}  // namespace

TEST_CASE("the fit's rotation is the polar decomposition's, flat, straight and mirrored ones too",
          "[grains][shape]") {
  // A = R0 S with S symmetric positive definite (singular values 0.3 to 3): R is R0. A mirrored
  // A (det < 0): the rotation nearest it, Eigen's SVD with the smallest singular value's
  // direction turned. A flat A (rank 2: a sheet of grains) has one such rotation too; a
  // straight one (rank 1: a line of grains) takes its direction to A's image and is a rotation,
  // the turn about the line free (the goals do not depend on it); A = 0 gives the identity.
  // Double precision and a 3 x 3 matrix: within 1e-12 of the reference.
  std::mt19937 rng(11);
  auto is_rotation = [](const M3& R) {
    return (R * R.transpose() - M3::Identity()).cwiseAbs().maxCoeff() < 1e-12 &&
           std::fabs(R.determinant() - 1.0) < 1e-12;
  };
  for (int trial = 0; trial < 200; ++trial) {
    const M3 R0 = random_rotation(rng), Q = random_rotation(rng);
    const Eigen::Vector3d d(0.3 + 2.7 * unit(rng), 0.3 + 2.7 * unit(rng), 0.3 + 2.7 * unit(rng));
    const M3 S = Q * d.asDiagonal() * Q.transpose();
    INFO("trial " << trial);
    CHECK((rotation_of(R0 * S) - R0).cwiseAbs().maxCoeff() < 1e-12);
    const M3 mirrored = R0 * S * Eigen::Vector3d(1, 1, -1).asDiagonal();
    CHECK(is_rotation(rotation_of(mirrored)));
    CHECK((rotation_of(mirrored) - reference(mirrored)).cwiseAbs().maxCoeff() < 1e-12);
    const M3 flat = R0 * Eigen::Vector3d(d.x(), d.y(), 0).asDiagonal() * Q.transpose();
    CHECK(is_rotation(rotation_of(flat)));
    CHECK((rotation_of(flat) - reference(flat)).cwiseAbs().maxCoeff() < 1e-12);
    const Eigen::Vector3d u = R0.col(0), v = Q.col(1);
    const M3 straight = d.x() * u * v.transpose();
    CHECK(is_rotation(rotation_of(straight)));
    CHECK((rotation_of(straight) * v - u).cwiseAbs().maxCoeff() < 1e-12);
  }
  CHECK(rotation_of(M3::Zero()) == M3::Identity());
}

TEST_CASE("use_opencl: the device projects rigid shapes as the host does, bit for bit",
          "[opencl][shape]") {
  // Three components, of 2, 65 and 300 grains (two lanes of one grain; 64 lanes, the first with
  // two; 64 lanes of four or five), a hundred free grains among them, their rest shapes turned,
  // stretched by up to 5 % and moved:
  // each grain's rest offset its place in the rest shape less the shape's centre. The lower
  // grains stand in a moving ground (a plane entry each: surface at y = 0, normal +y, the
  // surface moving at 0.3 m/s along x) and a third of those already carry a normal sum, so that
  // the fit, the shift out of the planes and the body's friction all act (checked: each moves
  // a body). One projection on the device (run_sequential with no contacts: the shapes alone)
  // and on the host (project_components): the same positions and normal sums, bit for bit.
  std::mt19937 rng(5);
  const std::vector<size_t> sizes = {2, 65, 300};
  const size_t free_grains = 100;
  size_t n = free_grains;
  for (size_t s : sizes) n += s;
  std::vector<float> p(3 * n + 1, 0.0f), P(3 * n), rest(3 * n, 0.0f), mass(n), radius(n, 0.05f);
  std::vector<gr_uint> offsets = {0}, members;
  std::vector<gr_uint> plane_offsets = {0};
  std::vector<float> plane, normal;
  // grains in a shuffled order: a component's members are not adjacent
  std::vector<gr_uint> order(n);
  for (size_t i = 0; i < n; ++i) order[i] = gr_uint(i);
  std::shuffle(order.begin(), order.end(), rng);
  size_t next = 0;
  for (size_t s : sizes) {
    const M3 turn = random_rotation(rng);
    const Eigen::Vector3d at(4.0 * unit(rng) - 2.0, 0.2, 4.0 * unit(rng) - 2.0);
    std::vector<Eigen::Vector3d> shape;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (size_t k = 0; k < s; ++k) {
      shape.emplace_back(0.4 * unit(rng) - 0.2, 0.4 * unit(rng) - 0.2, 0.4 * unit(rng) - 0.2);
      centre += shape.back();
    }
    centre /= double(s);
    for (size_t k = 0; k < s; ++k) {
      const gr_uint i = order[next++];
      members.push_back(i);
      mass[i] = 0.5f + unit(rng);
      const Eigen::Vector3d o = shape[k] - centre;
      const Eigen::Vector3d stretch(1 + 0.05 * unit(rng), 1 - 0.05 * unit(rng), 1);
      const Eigen::Vector3d x = at + turn * o.cwiseProduct(stretch);
      for (int a = 0; a < 3; ++a) {
        rest[3 * i + a] = float(o[a]);
        p[3 * i + a] = float(x[a]);
      }
    }
    offsets.push_back(gr_uint(members.size()));
  }
  for (; next < n; ++next) {
    const gr_uint i = order[next];
    mass[i] = 1.0f;
    for (int a = 0; a < 3; ++a) p[3 * i + a] = 4.0f * unit(rng) - 2.0f;
  }
  for (size_t i = 0; i < n; ++i) {
    // the start: each grain 1 cm back along x and up from where it is now
    for (int a = 0; a < 3; ++a)
      P[3 * i + a] = p[3 * i + a] + (a == 0 ? -0.01f : a == 1 ? 0.01f : 0);
    if (p[3 * i + 1] < 0.12f) {
      const float entry[9] = {p[3 * i], 0.0f, p[3 * i + 2], 0, 1, 0, 0.3f, 0, 0};
      plane.insert(plane.end(), entry, entry + 9);
      normal.push_back(normal.size() % 3 == 0 ? 0.002f : 0.0f);
    }
    plane_offsets.push_back(gr_uint(normal.size()));
  }
  REQUIRE(normal.size() > 20);  // the premise: grains of the components stand in the ground

  gr_grains g{};
  g.P = P.data();
  g.radius = radius.data();
  g.mass = mass.data();
  g.plane_offsets = plane_offsets.data();
  g.plane = plane.data();
  gr_params prm{};
  prm.friction_with_colliders = 1.0f;
  prm.static_threshold = 0.5f;
  prm.scale_kinetic = 0.75f;
  prm.dt = 1.0f / 240;
  gr_shapes sh;
  sh.offsets = offsets.data();
  sh.members = members.data();
  sh.rest = rest.data();
  sh.mass = mass.data();

  // the host: fit alone, fit and shift, fit, shift and friction (each moves a body)
  std::vector<float> fit = p, shifted = p, host = p, host_normal = normal;
  gr_grains planeless = g;
  planeless.plane_offsets = nullptr;
  sh.collider_normal = nullptr;
  project_components(sh, planeless, prm, fit.data(), sizes.size(), 2);
  project_components(sh, g, prm, shifted.data(), sizes.size(), 1);
  sh.collider_normal = host_normal.data();
  project_components(sh, g, prm, host.data(), sizes.size(), 2);
  CHECK(fit != p);
  CHECK(shifted != fit);
  CHECK(host != shifted);
  // grains in no component stay
  for (size_t k = members.size(); k < n; ++k) {
    const gr_uint i = order[k];
    for (int a = 0; a < 3; ++a) CHECK(host[3 * i + a] == p[3 * i + a]);
  }

  // the device: one pass of no contacts, the shapes after it
  opencl::Iterations device;
  REQUIRE(device.shapes_there());
  opencl::IterationSizes size;
  size.n = n;
  size.plane_entries = normal.size();
  const gr_uint zero = 0;
  opencl::SequentialContacts s;
  s.block_start = &zero;
  s.block_wave = &zero;
  s.wave_start = &zero;
  opencl::ShapeArrays shapes;
  shapes.offsets = offsets.data();
  shapes.members = members.data();
  shapes.components = sizes.size();
  shapes.rest = rest.data();
  shapes.mass = mass.data();
  std::vector<float> there = p, there_normal = normal;
  shapes.collider_normal = there_normal.data();
  shapes.entries = there_normal.size();
  s.shapes = &shapes;
  device.run_sequential(g, prm, size, there.data(), s, 1);
  size_t differ = 0;
  for (size_t k = 0; k < 3 * n; ++k) differ += there[k] != host[k];
  CHECK(differ == 0);
  CHECK(there_normal == host_normal);
}

TEST_CASE("use_opencl: with rigid shapes on the device a substep's passes do not cross",
          "[opencl][shape][gauss_seidel]") {
  // The tilted cube (tilted_cube) landing on the ground, on the device until it stands there (its
  // lowest grain within half a radius of resting). The shapes are projected there after each pass
  // (gr_k_shapes), so the contact list is built and kept there as without shapes, and the
  // components and rest offsets stay there while they hold (ShapeArrays::generation). Four more
  // substeps: each sends under 1 KiB (the colliders, the force, flags) and receives the written
  // positions and velocities (24 B a grain), its reductions' partial results (61,440 B, as in "what
  // crosses between the host and the device each substep") and under 4 KiB more. Projecting them on
  // the host had each pass's positions cross both ways (12 B a grain a pass each way), the list
  // built on the host sent and brought back (56 B a contact), and the shapes' arrays sent each
  // substep (16 B a grain). Then one more substep from that state (a copy of the scene, which sends
  // its arrays first) with 5 passes and with 20: the traffic does not grow with the passes (the two
  // differ by under 4 KiB each way, a pass's flags and largest moves).
  test::Scene sc = tilted_cube();
  sc.s.use_opencl = true;
  const float r = 0.05f;
  const double n = double(sc.size());
  float lowest = 1e9f;
  for (int k = 0; k < 120 && lowest > 1.5f * r; ++k) {
    sc.substep();
    lowest = 1e9f;
    for (size_t i = 0; i < sc.size(); ++i) lowest = std::min(lowest, sc.pos(i).y);
  }
  REQUIRE(lowest <= 1.5f * r);  // the premise: it stands on the ground (shift and friction act)
  for (int k = 0; k < 4; ++k) {
    const opencl::Traffic before = sc.solver.device_traffic();
    sc.substep();
    const opencl::Traffic after = sc.solver.device_traffic();
    const double sent = double(after.sent - before.sent),
                 received = double(after.received - before.received);
    INFO("substep " << k << ": sent " << sent << " B, received " << received << " B");
    CHECK(sent < 1024);
    CHECK(received >= 24 * n);
    CHECK(received < 24 * n + 61440 + 4096);
  }
  auto traffic = [&](int passes) {
    test::Scene one = sc;
    one.s.constraint_iterations = passes;
    const opencl::Traffic before = one.solver.device_traffic();
    one.substep();
    const opencl::Traffic after = one.solver.device_traffic();
    return std::pair{double(after.sent - before.sent), double(after.received - before.received)};
  };
  const auto [sent5, received5] = traffic(5);
  const auto [sent20, received20] = traffic(20);
  INFO("5 passes: sent " << sent5 << " B, received " << received5 << "; 20 passes: sent " << sent20
                         << " B, received " << received20);
  CHECK(std::fabs(sent20 - sent5) < 4096);
  CHECK(std::fabs(received20 - received5) < 4096);
}

TEST_CASE("use_opencl: rigid shapes projected on the device give the host's projection's bits",
          "[opencl][shape]") {
  // The tilted cube landing on the ground and settling, 60 substeps, on the device with the
  // shapes projected there (after each pass within the solve; with jacobi within the one call of
  // its iterations, after each iteration and the friction pass) and with them projected on the
  // host between passes each a device call of its own (host_shapes): the same functions on the
  // same floats, so the same positions and velocities, bit for bit, every substep. Both solvers;
  // jacobi with its friction pass once and after each iteration, with Chebyshev's step, and with
  // its rows and planes found again during the iterations (there too, within the one call: the
  // shapes' friction then reads the rebuilt planes and their carried sums there).
  struct Variant {
    const char* name;
    int solver;
    bool accurate;
    float rho;
    bool rebuild;
  };
  for (const Variant& v :
       {Variant{"gauss_seidel", kContactGaussSeidel, false, 0.0f, false},
        Variant{"jacobi", kContactJacobi, false, 0.0f, false},
        Variant{"jacobi, accurate friction", kContactJacobi, true, 0.0f, false},
        Variant{"jacobi, Chebyshev", kContactJacobi, false, 0.9f, false},
        Variant{"jacobi, rows and planes found again", kContactJacobi, false, 0.0f, true}}) {
    INFO(v.name);
    test::Scene there = tilted_cube();
    there.s.use_opencl = true;
    there.s.contact_solver = v.solver;
    there.s.accurate_friction = v.accurate;
    there.s.chebyshev_rho = v.rho;
    there.s.update_neighbors_during_iterations = v.rebuild;
    there.s.update_collisions_during_iterations = v.rebuild;
    test::Scene here = there;
    here.s.host_shapes = true;
    int differ = 0, chained = 0;
    for (int k = 0; k < 60; ++k) {
      there.substep();
      here.substep();
      differ += there.P != here.P || there.v != here.v;
      chained += there.solver.finished_on_device() && !here.solver.finished_on_device();
    }
    CHECK(differ == 0);
    // (jacobi: the substep chained there, the shapes with it; the host's keep it here)
    if (v.solver == kContactJacobi) CHECK(chained == 60);
    float lowest = 1e9f;
    for (size_t i = 0; i < there.size(); ++i) lowest = std::min(lowest, there.pos(i).y);
    CHECK(lowest < 0.075f);  // the premise: it landed (the shift and the friction acted)
  }
}
