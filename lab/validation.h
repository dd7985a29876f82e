// `grains-lab laws`: validation against published granular laws (DESIGN §7 (c)). Runs the scenes in
// bench/validation/ (column collapse, silo discharge, poured pile) at several sizes, measures
// each outcome from the particles, fits the laws, and writes DIR/validation.csv and a Markdown
// report (VALIDATION.md). See bench/validation/README.md for the laws, sources and methods.
//
// The measurements and fits are plain functions over particle stores so that tests
// (tests/validation/) can run the quick plan's cases and assert the laws themselves.
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "engine/particles.h"

namespace CLI {
class App;
}

namespace grains {

// ---------------------------------------------------------------------------------------------
// Fits

// Least squares y = intercept + slope x; r2 is the coefficient of determination.
struct LineFit {
  double slope = 0, intercept = 0, r2 = 0;
  size_t n = 0;
};
LineFit fit_line(const std::vector<double>& x, const std::vector<double>& y);

// Least squares in log-log: y = prefactor x^exponent (every x, y > 0); r2 of the log fit.
struct PowerFit {
  double exponent = 0, prefactor = 0, r2 = 0;
};
PowerFit fit_power(const std::vector<double>& x, const std::vector<double>& y);

// ---------------------------------------------------------------------------------------------
// Measurements (d: grain diameter, m)

// Outer radius of a deposit around the vertical axis through (cx, cz): walking out from the
// ring of the median radius in rings d wide, where the grains' projected cover (grains whose
// centre is in the ring, each a disc of diameter d, over the ring's area) first falls below
// one half, interpolated linearly between ring centres. Half a monolayer is where a continuous
// deposit ends; a few grains thrown beyond do not count. On a lattice column of radius R0 (cells
// d wide) it returns R0 - 0.15 d for one layer up to R0 + 0.5 d for forty.
double deposit_radius(const ParticleStore& pts, double cx, double cz, double d);

// Highest grain top (y + pscale) above y = 0.
double deposit_height(const ParticleStore& pts);

// Slope of a pile around the vertical axis through (cx, cz), from its moving grains (mass > 0)
// below y_max. `radius` is their deposit_radius R. In each of `sectors` azimuthal sectors the
// surface height at radius r is the highest grain top (y + pscale) in a ring d wide; a line
// fitted to the rings between 0.2 R and 0.8 R (the flank: neither the tip, where the pour
// stream or a lone standing chain may sit, nor the toe) gives that sector's angle atan(-slope).
// angle_deg is the mean over sectors with at least 3 such rings, spread_deg their standard
// deviation; height is the median over sectors of the highest top.
struct PileSlope {
  double angle_deg = 0, spread_deg = 0, height = 0, radius = 0;
  int sectors = 0;
};
PileSlope pile_slope(const ParticleStore& pts, double cx, double cz, double d, double y_max = 1e30,
                     int sectors = 8);

// ---------------------------------------------------------------------------------------------
// Experiments. Each loads its scene with overrides (bench/validation/README.md), runs it in
// this process and measures it. `threads` <= 0: OpenMP's default.

// Common solver settings of a run.
struct LawSettings {
  double d = 0.02;  // grain diameter = source separation = particle_separation (m)
  int substeps = 8;
  int iterations = 40;
  // the solver's and grains node's defaults instead (substeps the fewest, error control
  // picking them each frame): the plan's (0, 0) setting
  bool error_control = false;
  double friction = 0.5;  // grains.friction_with_particles
  // grains.contact_solver; empty: the node's default (contact_solver_of)
  std::string contact_solver;
};

// Axisymmetric column collapse (Lube et al. 2004; Lajeunesse et al. 2004): a loose jittered
// lattice (kCollapseSpacing d apart) carved to a cylinder of radius R0 = radius_grains d falls
// and settles in a frictionless tube (a mesh collider of radius R0 + d/2) on a rough bed of fixed
// grains (data/rough_bed.ply) into a random packing; when it has come to rest the tube widens a
// hundredfold and the column collapses. Run-out (R_inf - R0) / R0 measured by deposit_radius
// once the deposit stopped. The lattice is built 1 / kCollapseCompaction times the planned
// height so that the settled column stands about aspect x R0; `aspect` is what it measured.
constexpr double kCollapseSpacing = 1.35;     // lattice spacing / d
constexpr double kCollapseCompaction = 0.36;  // settled / built height (full plan: 0.31-0.37 above a = 1, 0.43 at 0.58)
constexpr double kBedRadius = 1.18;           // m: data/rough_bed.ply's, less a grain
struct CollapseResult {
  double planned = 0;     // the aspect ratio asked for
  double aspect = 0;      // H0 / R0 of the settled column at release
  // m; h0 the settled column's height at release: the median over 8 sectors of the highest
  // grain top (pile_slope's height: a grain bouncing on the column does not count)
  double r0 = 0, h0 = 0;
  double release = 0;     // s: the tube widens after this frame
  double h_built = 0;     // m, the lattice's height
  size_t grains = 0;
  double r0_measured = 0;    // deposit_radius of the column at release (m)
  double r_inf = 0;          // deposit_radius at the last frame (m)
  double r_inf_earlier = 0;  // the same 0.25 s before: the run-out had stopped if they agree
  double runout = 0;         // (r_inf - r0) / r0
  double h_inf = 0;          // final deposit height (m), as h0
  int frames = 0;
  double seconds = 0;  // wall time of the run
};
// The contact solver a run uses: s.contact_solver, or the grains node's declared default.
std::string contact_solver_of(const LawSettings& s);

CollapseResult run_collapse(const std::string& scene, double aspect, int radius_grains,
                            const LawSettings& s, int threads);

// Silo discharge (Beverloo et al. 1961): a square silo `width_grains` d wide filled
// `fill_grains` d high, a square orifice of side D = orifice_grains d in its floor; grains that
// fall through are killed. The discharge rate is the slope of the grain count over the window
// [t_start, t_end] (s).
struct SiloResult {
  double orifice = 0;                      // D (m)
  size_t grains = 0;                       // at the start
  double rate = 0;                         // grains / s over the window (least squares)
  double rate_first = 0, rate_second = 0;  // over the window's halves: steadiness
  double r2 = 0;                           // of the count's linear fit over the window
  double number_density = 0;  // grains / m^3 in the silo at t_start (grains over silo volume
                              // up to the fill's 95th-percentile height)
  double drained = 0;         // fraction of the grains gone by t_end
  int frames = 0;
  double seconds = 0;
};
struct SiloSize {
  int width_grains = 24;
  int fill_grains = 24;
  double t_start = 0.75, t_end = 1.75;
};
SiloResult run_silo(const std::string& scene, int orifice_grains, const SiloSize& size,
                    const LawSettings& s, int threads);

// Beverloo W = C rho_b sqrt(g) (D - k d)^(5/2), in grains: rate = C n_b sqrt(g) (D - k d)^n.
struct BeverlooFit {
  double exponent_k14 = 0, r2_k14 = 0;  // n from a log-log fit with k = 1.4 (Nedderman)
  // n = 5/2 fixed, the Beverloo plot: rate^(2/5) is linear in D, zero at D = k d
  double k_linear = 0, r2_linear = 0;
  double exponent_free = 0, k_free = 0, r2_free = 0;  // n and k together (k in [0, D_min/d)):
                                                      // ill-conditioned over D/d = 5..9
  double c = 0;         // mean of rate / (n_b sqrt(g) (D - 1.4 d)^2.5): C at n = 2.5, k = 1.4
  double c_spread = 0;  // max - min of that ratio over the orifices
};
BeverlooFit fit_beverloo(const std::vector<SiloResult>& runs, double d);

// Angle of repose (fixed-funnel method): a square hopper `hopper_grains` d wide, filled
// `fill_grains` d high, empties through a square hole of side orifice_grains d in its floor
// (top at hopper_floor m) onto a rough bed of fixed grains (data/rough_bed.ply); the colliders are
// frictionless, grain-grain friction is `friction`. pile_slope of the grains below the hopper at
// the last frame, and one second earlier (the difference is creep).
struct ReposeResult {
  double friction = 0;
  size_t grains = 0;          // poured (moving) grains
  size_t left_in_hopper = 0;  // of them still above the hopper's floor at the end
  PileSlope slope, slope_earlier;
  double seconds = 0;
  int frames = 0;
};
struct ReposeSize {
  int hopper_grains = 12;      // inner width / d
  int fill_grains = 18;        // fill height / d
  int orifice_grains = 6;      // hole / d
  double hopper_floor = 0.36;  // m: the hole's height
  double bed_radius = 0.45;    // m, of the rough bed kept (the file's is 1.2 m)
  int frames = 144;
  double funnel_deg = 60;  // the funnel's plates from the horizontal
};
ReposeResult run_repose(const std::string& scene, double friction, const ReposeSize& size,
                        const LawSettings& s, int threads);

// ---------------------------------------------------------------------------------------------
// The plan: which cases a full or --quick run takes. Tests run the quick plan.

struct ValidationPlan {
  LawSettings settings;  // d and friction; substeps and iterations come from solver_settings
  // (substeps, iterations) each experiment runs at: (0, 0), the node and solver defaults with
  // error control (what a user gets, and the quick plan's), and in the full plan 8 x 40 fixed
  // beside it
  std::vector<std::pair<int, int>> solver_settings;
  std::vector<double> aspects;  // column collapse aspect ratios
  int column_radius_grains = 10;
  std::vector<int> orifices;  // D / d
  SiloSize silo;
  std::vector<double> frictions;  // angle of repose
  ReposeSize pile;
};
ValidationPlan validation_plan(bool quick);
// The settings of one of a plan's solver_settings: (0, 0) the node and solver defaults with error
// control (their declared substeps and iterations), else those fixed substeps and iterations.
LawSettings law_settings(const ValidationPlan& plan, std::pair<int, int> solver_setting);

// Published expectations (bench/validation/README.md).
double lube2004_runout(double a);        // 1.24 a (a <= 1.7), 1.6 a^(1/2) above
double lajeunesse2004_runout(double a);  // 1.0 a (a <= 0.74), 2.0 a^(1/2) above
constexpr double kReposeDemLow = 18.7, kReposeDemHigh = 47.0;  // deg, DEM spheres (README)
constexpr double kBeverlooExponent = 2.5, kBeverlooK = 1.4, kBeverlooC = 0.58;

struct ValidationOptions {
  std::string scenes_dir = "bench/validation";
  std::string out_dir = "out/validation";
  std::string md_path = "VALIDATION.md";
  bool quick = false;
  int threads = 0;                   // <= 0: every core
  std::vector<std::string> only;     // empty: all of collapse, silo, repose
  int substeps = 0, iterations = 0;  // > 0: replace the plan's solver setting
  bool defaults = false;             // replace it with the defaults and error control
  double friction = -1;              // >= 0: replace the plan's friction (collapse and silo)
  std::string contact_solver;        // not empty: replace the plan's (jacobi)
  std::string command;               // the command line, for the report
};

// Runs the plan; writes DIR/validation.csv and the Markdown report. Returns the exit code
// (0; 2 for a missing or bad scene). A law that does not hold is reported, not an error.
int run_validation(const ValidationOptions& options);

// The documented header of validation.csv.
const char* validation_csv_header();

CLI::App* add_validation_command(CLI::App& app, ValidationOptions& options, int argc, char** argv);

}  // namespace grains
