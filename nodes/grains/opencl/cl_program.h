// OpenCL objects the device code shares (device.cpp makes them, iterations.cpp uses them).
#pragma once
#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>

#include <string>
#include <vector>

#include "nodes/grains/opencl/sources.h"

namespace grains::opencl {

// Device `device` of platform `platform` (indices as platforms() lists them); null with
// *problem set when there is none.
cl_device_id device_id(size_t platform, size_t device, std::string* problem);

// The grains program (grains.cl and the kernel headers, embedded at build time) built for
// OpenCL C 1.2 on device d of ctx; null with *log holding why (the compiler's log on a failed
// build). On success *log holds the compiler's warnings, if any.
cl_program build_program(cl_context ctx, cl_device_id d, std::string* log);
// ... or the program of file `main` of `files` (program_text)
cl_program build_program(cl_context ctx, cl_device_id d, const std::vector<SourceFile>& files,
                         const std::string& main, std::string* log);

}  // namespace grains::opencl
