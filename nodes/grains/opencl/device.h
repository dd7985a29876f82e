// OpenCL platforms and devices, and building the grains kernels on one. `grains devices` lists
// what the OpenCL loader finds and whether each device builds the kernels; a grains node with
// use_opencl runs on the device chosen_device() names (opencl/iterations.h).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace grains::opencl {

struct Device {
  std::string name;
  std::string type;       // "cpu", "gpu", "accelerator" or "other"
  std::string version;    // CL_DEVICE_VERSION
  std::string c_version;  // CL_DEVICE_OPENCL_C_VERSION
  uint32_t compute_units = 0;
  uint64_t global_memory = 0;  // bytes
  uint64_t largest_buffer = 0;  // bytes: CL_DEVICE_MAX_MEM_ALLOC_SIZE, the most one buffer holds
};

struct Platform {
  std::string name, vendor, version;
  std::vector<Device> devices;
};

// Every platform the OpenCL loader finds, with its devices. None: returns an empty list and
// sets *problem to why (no loader configuration, no driver installed).
std::vector<Platform> platforms(std::string* problem);

// A device by its place in platforms(): "P:D", platform P's device D.
struct DeviceChoice {
  size_t platform = 0, device = 0;
};
// Parses "P:D" (two non-negative integers); "" and *problem set when it is not one.
bool parse_device_choice(const std::string& text, DeviceChoice* out, std::string* problem);
// "" when `choice` names a device of `list`, else why not, naming what there is.
std::string choice_problem(const std::vector<Platform>& list, const DeviceChoice& choice);

// The device a grains node with use_opencl runs on: GRAINS_OPENCL_DEVICE ("P:D") when set, else
// the first platform's first device. Returns false with *problem set when there is no platform,
// the variable is malformed or names no device.
bool chosen_device(DeviceChoice* out, std::string* problem);

// GRAINS_OPENCL_MAX_BUFFER_MIB: the most MiB one device buffer may take, below the device's own
// CL_DEVICE_MAX_MEM_ALLOC_SIZE (a driver that reports more than it can give; tests of the parts
// the contacts are split into). Unset: *bytes = 0 (no cap). Malformed: false, *problem says why.
// chosen_device() checks it too.
bool buffer_cap(uint64_t* bytes, std::string* problem);

// GRAINS_OPENCL_SWEEP_ITEMS: the work-items that share each block of gauss_seidel's contacts in
// a sweep, 1 to 1024 (the result is the same bits for any; opencl/iterations.h). Unset: *items
// = 0 (the device's kind decides: 1 on a CPU, 64 elsewhere). Malformed: false, *problem says why.
// chosen_device() checks it too.
bool sweep_items(uint64_t* items, std::string* problem);

// GRAINS_OPENCL_HOST_CONTACTS: 1 has the host build gauss_seidel's contact list and look up its
// carried loads, as the CPU path does, and send it to the device; 0 or unset lets the device
// build it where it can (Iterations::build_sequential: the same list, bit for bit). For
// comparing the two. Malformed: false, *problem says why. chosen_device() checks it too.
bool host_contacts(bool* host, std::string* problem);

// GRAINS_OPENCL_HOST_SLEEP: 1 has the host make the grains node's sleeping test, reading the
// positions and velocities every substep; 0 or unset lets the device make it where it can
// (Iterations::sleep_begin, sleep_end: the same decisions, bit for bit). For comparing the two.
// Malformed: false, *problem says why. chosen_device() checks it too.
bool host_sleep(bool* host, std::string* problem);

// GRAINS_OPENCL_NO_FP64: 1 builds the program as for a device without double precision
// (kernels/prelude.h, GR_DOUBLES: no rows, rigid shapes, mesh queries, sleeping test or motion
// measure there; the host makes them, the same frames); 0 or unset builds it for the device. For
// testing the host's stages on devices that all have doubles. Malformed: false, *problem says
// why. chosen_device() checks it too.
bool no_fp64(bool* off, std::string* problem);

struct BuildResult {
  bool ok = false;
  double seconds = 0;  // wall time of the build
  std::string log;     // the compiler's log (its errors when !ok)
};

// Builds the grains program (opencl/grains.cl and the kernel headers, as embedded at build time)
// for OpenCL C 1.2 on device `device` of platform `platform` (indices into platforms()).
BuildResult build_kernels(size_t platform, size_t device);

}  // namespace grains::opencl
