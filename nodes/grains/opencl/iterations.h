// The substep's Jacobi iterations and friction passes on an OpenCL device (a grains node with
// use_opencl). GrainsSolver::substep prepares the substep on the CPU as always (prediction,
// neighbour rows, collider planes, contact history, pre-stabilization), hands the iterations'
// inputs to run(), and finishes on the CPU (velocity, final collisions, history, strain). The
// kernels are gr_iterate and gr_friction_pass, the functions the CPU loop calls
// (opencl/grains.cl). Each grain writes only its own outputs and sums its contacts in row order,
// so a device gives the same result run to run.
#pragma once
#include <cstddef>
#include <memory>
#include <string>

#include "nodes/grains/kernels/iterate.h"

namespace grains::opencl {

// How much of each array run() reads: grains, neighbour entries, collider plane entries,
// explicit-constraint primitives, and the row scratch of the contact loop.
struct IterationSizes {
  size_t n = 0;
  size_t pair_entries = 0;
  size_t plane_entries = 0;
  size_t prims = 0;
  size_t row_length = 0;  // floats of one grain's overlap row (whole blocks of GR_LANES)
};

class Iterations {
 public:
  // Opens the device chosen_device() names and builds the program there; throws
  // std::runtime_error saying why when it cannot.
  Iterations();
  ~Iterations();
  Iterations(const Iterations&) = delete;
  Iterations& operator=(const Iterations&) = delete;

  // `iterations` Jacobi iterations of p (3 n + 1 floats, in and out) with g's arrays and prm,
  // then the friction pass: after every iteration when `accurate_friction`, else once after
  // them; none when !friction_pass. acc's sums (pair, collider, collider_dx, friction_dx: host
  // arrays, each null when unused) are read as they start and written back as they end.
  void run(const gr_grains& g, const gr_params& prm, const IterationSizes& size, float* p,
           const gr_normal_sums& acc, int iterations, bool friction_pass, bool accurate_friction);

  const std::string& device_name() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace grains::opencl
