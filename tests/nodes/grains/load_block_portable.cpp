// The contact loop's block load as it is compiled without AVX2 (and as OpenCL has it), for
// test_load_block.cpp to compare with the vector version the rest of the build uses.
#define GR_PORTABLE_LOADS
#include "nodes/grains/kernels/prelude.h"

void load_block_portable(const float* a, const gr_uint* j, float* x, float* y, float* z) {
  gr_load_block(a, j, x, y, z);
}
