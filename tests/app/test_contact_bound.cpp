// grains_contact_bound (bench/contact_bound.cpp): the rows it measures on a pile whose candidates
// and contacts are known exactly, and its errors.
#include <catch2/catch.hpp>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <sys/wait.h>

#include "engine/geometry_io.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;

namespace {

int run_bound(const std::string& args, const std::string& log) {
  std::string cmd = std::string(GRAINS_CONTACT_BOUND) + " " + args + " > " + log + " 2>&1";
  int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// the number after `key` on the line holding it
double number_after(const std::string& text, const std::string& key) {
  size_t at = text.find(key);
  REQUIRE(at != std::string::npos);
  return std::strtod(text.c_str() + at + key.size(), nullptr);
}

}  // namespace

TEST_CASE("contact_bound counts a lattice's candidates and contacts and times three loops",
          "[bench]") {
  // 6 x 6 x 6 grains of radius r, spacing 1.9 r: face neighbours (1.9 r) touch; edge diagonals
  // (1.9 r sqrt 2 = 2.69 r) are candidates within 1.5 x 2r = 3 r but apart; body diagonals
  // (3.29 r) and two spacings (3.8 r) are out. Ordered pairs: faces 3 x (5 x 6 x 6) x 2 = 1080,
  // edge diagonals 3 planes x 6 layers x 25 squares x 2 diagonals x 2 = 1800, over 216 grains.
  const float r = 0.01f, h = 1.9f * r;
  ParticleStore pts;
  pts.add_points(216);
  float* P = pts.v3("P");
  float* pscale = pts.f("pscale");
  for (int k = 0; k < 216; ++k) {
    P[3 * k] = h * float(k % 6);
    P[3 * k + 1] = h * float(k / 6 % 6);
    P[3 * k + 2] = h * float(k / 36);
    pscale[k] = r;
  }
  std::string dir = temp_dir("contact_bound");
  write_ply(dir + "/lattice.ply", pts, {});
  REQUIRE(run_bound(dir + "/lattice.ply --iterations 2 --repeat 1 --threads 2", dir + "/log") == 0);
  const std::string out = read_text(dir + "/log");
  CHECK(number_after(out, "lattice.ply: ") == 216);
  CHECK(number_after(out, "): ") == Approx((1080.0 + 1800.0) / 216).epsilon(1e-3));
  CHECK(number_after(out, "per grain, ") == Approx(1080.0 / 216).epsilon(1e-3));
  CHECK(number_after(out, "that size: ") == Approx(8 * (1080.0 + 1800.0) / 216).margin(0.5));
  CHECK(number_after(out, "engine, with sums") > 0);
  CHECK(number_after(out, "engine, no sums") > 0);
}

TEST_CASE("contact_bound rejects bad input with exit code 2", "[bench]") {
  std::string dir = temp_dir("contact_bound_bad");
  CHECK(run_bound("", dir + "/log") == 2);
  CHECK(run_bound(dir + "/missing.ply", dir + "/log") == 2);
  CHECK(read_text(dir + "/log").find("missing.ply") != std::string::npos);
  ParticleStore pts;
  pts.add_points(2);
  pts.f("pscale")[0] = 0.01f;
  pts.f("pscale")[1] = 0.02f;
  write_ply(dir + "/mixed.ply", pts, {});
  CHECK(run_bound(dir + "/mixed.ply", dir + "/log") == 2);
  CHECK(read_text(dir + "/log").find("radii must be equal") != std::string::npos);
  write_ply(dir + "/ok.ply", ParticleStore(), {});
  CHECK(run_bound(dir + "/ok.ply --iterations 0", dir + "/log") == 2);
}
