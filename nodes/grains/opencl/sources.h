// The OpenCL program's source files, embedded at build time (cmake/embed_kernels.cmake): the
// kernel headers of nodes/grains/kernels/ and grains.cl, which includes them.
#pragma once
#include <string>
#include <vector>

namespace grains::opencl {

struct SourceFile {
  const char* name;  // file name, as grains.cl includes it
  const char* text;
};

const std::vector<SourceFile>& kernel_sources();

// File `main` of `files` as one text: each line `#include "NAME"` naming one of the files is
// replaced by that file's text, expanded the same way, at every place it is included (include
// guards keep one copy of each, as the compiler's own inclusion would); `#line` directives keep
// the compiler's messages naming the file and line they came from. A program built from it
// needs no include path: the same text and options every run, which lets a driver's cache of
// built programs (PoCL's, NVIDIA's) find it instead of building it again.
std::string program_text(const std::vector<SourceFile>& files, const std::string& main);

}  // namespace grains::opencl
