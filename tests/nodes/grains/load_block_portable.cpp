// The contact loop's block load and the friction sums' block update as they are compiled without
// AVX2 (and as OpenCL has them), for test_load_block.cpp to compare with the vector versions the
// rest of the build uses.
#define GR_PORTABLE_LOADS
#include "nodes/grains/kernels/prelude.h"

void load_block_portable(const float* a, const gr_uint* j, float* x, float* y, float* z) {
  gr_load_block(a, j, x, y, z);
}

void add_block_portable(gr_uint* sum, const float* add, float s) { gr_add_block(sum, add, s); }
