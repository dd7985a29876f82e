// The OpenCL program's source files, embedded at build time (cmake/embed_kernels.cmake): the
// kernel headers of nodes/grains/kernels/ and grains.cl, which includes them.
#pragma once
#include <vector>

namespace grains::opencl {

struct SourceFile {
  const char* name;  // file name, as grains.cl includes it
  const char* text;
};

const std::vector<SourceFile>& kernel_sources();

}  // namespace grains::opencl
