// grains_mesh_query: what a triangle-mesh collider costs the solver, per distance query.
//
//   grains_mesh_query FRAME.ply MESH [--repeat R]
//
// Reads a frame written by `grains run` (the grains' positions) and an OBJ or PLY mesh in the
// same frame, builds the mesh's shape (engine/mesh_shape.h: the hierarchy, timed), then times
// MeshShape::distance at every grain's position, R times over, on one thread: exact everywhere,
// and bounded as the solver asks (`within` 2 x the grain's radius: the contact planes' range
// 1.5 r plus a substep's motion, at most r / 2), beside the analytic sphere's distance at the
// same points for scale. The solver asks each collider about each grain about twice a substep
// (the contact planes and the final collision pass), so ns per query x 2 against the substep's
// cost per grain (stats.csv: wall_ms / substeps / points) is the mesh's share of a substep. Exit code 2 for bad arguments or unreadable files.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "engine/collider.h"
#include "engine/geometry_io.h"
#include "engine/mesh_shape.h"

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  using namespace grains;
  if (argc != 3 && !(argc == 5 && std::string(argv[3]) == "--repeat")) {
    std::fprintf(stderr, "usage: grains_mesh_query FRAME.ply MESH [--repeat R]\n");
    return 2;
  }
  const int repeat = argc == 5 ? std::atoi(argv[4]) : 20;
  if (repeat <= 0) {
    std::fprintf(stderr, "grains_mesh_query: --repeat must be a positive integer\n");
    return 2;
  }
  try {
    const ParticleStore pts = read_ply(argv[1]);
    const Mesh mesh = read_mesh(argv[2]);
    auto t0 = Clock::now();
    std::string problem;
    const auto shape = MeshShape::build(mesh, &problem);
    const double build_s = seconds_since(t0);
    if (!shape) {
      std::fprintf(stderr, "grains_mesh_query: %s: %s\n", argv[2], problem.c_str());
      return 2;
    }
    const float* P = pts.v3_if("P");
    const float* radius = pts.f_if("pscale");
    const size_t n = pts.size();
    Shape sphere;
    sphere.kind = ShapeKind::Sphere;
    auto time_queries = [&](auto&& query) {
      double sum = 0;
      const auto t = Clock::now();
      for (int r = 0; r < repeat; ++r)
        for (size_t k = 0; k < n; ++k) {
          Vec3 nrm;
          sum += query(load3(P, k), &nrm, 2 * radius[k]) + nrm.y;
        }
      const double ns = 1e9 * seconds_since(t) / (double(repeat) * double(n));
      if (sum == 12345.678) std::printf(" ");  // keeps the loop
      return ns;
    };
    const double exact_ns =
        time_queries([&](const Vec3& p, Vec3* nrm, float) { return shape->distance(p, nrm); });
    const double within_ns = time_queries(
        [&](const Vec3& p, Vec3* nrm, float within) { return shape->distance(p, nrm, within); });
    const double sphere_ns =
        time_queries([&](const Vec3& p, Vec3* nrm, float) { return shape_distance(sphere, p, nrm); });
    std::printf("mesh: %zu triangles, %s, built in %.3f ms\n", shape->triangle_count(),
                shape->closed() ? "closed" : "open shell", 1e3 * build_s);
    std::printf("%zu grains x %d: mesh distance %.1f ns/query exact, %.1f ns/query within 2 r; "
                "analytic sphere %.1f ns/query\n",
                n, repeat, exact_ns, within_ns, sphere_ns);
  } catch (const GeometryError& e) {
    std::fprintf(stderr, "grains_mesh_query: %s\n", e.what());
    return 2;
  }
  return 0;
}
