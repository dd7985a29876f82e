#include "nodes/grains/opencl/device.h"

#include <chrono>
#include <cstdlib>
#include <sstream>
#include <stdexcept>

#include "nodes/grains/opencl/cl_program.h"
#include "nodes/grains/opencl/sources.h"

namespace grains::opencl {
namespace {

// A text property of a platform or device through OpenCL's two-call getters (the size, then
// the text), without its terminating zeros; "" when the driver has none.
template <class Object, class Info>
std::string info_text(cl_int (*get)(Object, Info, size_t, void*, size_t*), Object o, Info what) {
  size_t n = 0;
  if (get(o, what, 0, nullptr, &n) != CL_SUCCESS || n == 0) return "";
  std::string s(n, '\0');
  get(o, what, n, s.data(), nullptr);
  while (!s.empty() && s.back() == '\0') s.pop_back();
  return s;
}
std::string platform_text(cl_platform_id p, cl_platform_info what) {
  return info_text(clGetPlatformInfo, p, what);
}
std::string device_text(cl_device_id d, cl_device_info what) {
  return info_text(clGetDeviceInfo, d, what);
}

std::vector<cl_platform_id> platform_ids(cl_int* status) {
  cl_uint n = 0;
  *status = clGetPlatformIDs(0, nullptr, &n);
  if (*status != CL_SUCCESS || n == 0) return {};
  std::vector<cl_platform_id> ids(n);
  *status = clGetPlatformIDs(n, ids.data(), nullptr);
  if (*status != CL_SUCCESS) return {};
  return ids;
}

std::vector<cl_device_id> device_ids(cl_platform_id p) {
  cl_uint n = 0;
  if (clGetDeviceIDs(p, CL_DEVICE_TYPE_ALL, 0, nullptr, &n) != CL_SUCCESS || n == 0) return {};
  std::vector<cl_device_id> ids(n);
  if (clGetDeviceIDs(p, CL_DEVICE_TYPE_ALL, n, ids.data(), nullptr) != CL_SUCCESS) return {};
  return ids;
}

// the file an `#include "NAME"` line names (empty: the line includes nothing by that form)
std::string included_name(const std::string& line) {
  size_t k = line.find_first_not_of(" \t");
  if (k == std::string::npos || line[k] != '#') return {};
  k = line.find_first_not_of(" \t", k + 1);
  if (k == std::string::npos || line.compare(k, 7, "include") != 0) return {};
  k = line.find_first_not_of(" \t", k + 7);
  if (k == std::string::npos || line[k] != '"') return {};
  const size_t end = line.find('"', k + 1);
  if (end == std::string::npos || line.find_first_not_of(" \t\r", end + 1) != std::string::npos)
    return {};
  return line.substr(k + 1, end - k - 1);
}

void expand(const std::vector<SourceFile>& files, const std::string& name, int depth,
            std::string* out) {
  const char* text = nullptr;
  for (const SourceFile& f : files)
    if (name == f.name) text = f.text;
  // (an include cycle would recurse for ever: guarded files stop it long before this depth)
  if (!text || depth > 64) throw std::runtime_error("grains program: cannot expand " + name);
  *out += "#line 1 \"" + name + "\"\n";
  std::istringstream in(text);
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const std::string inner = included_name(line);
    bool ours = false;
    for (const SourceFile& f : files) ours = ours || inner == f.name;
    if (!ours) {
      *out += line + "\n";
      continue;
    }
    expand(files, inner, depth + 1, out);
    *out += "#line " + std::to_string(number + 1) + " \"" + name + "\"\n";
  }
}

}  // namespace

std::vector<Platform> platforms(std::string* problem) {
  cl_int status = CL_SUCCESS;
  const std::vector<cl_platform_id> ids = platform_ids(&status);
  if (ids.empty()) {
    *problem = "no OpenCL platform found (clGetPlatformIDs: " + std::to_string(status) +
               "): install an OpenCL driver, for example Debian's pocl-opencl-icd for the CPU";
    return {};
  }
  std::vector<Platform> out;
  for (cl_platform_id p : ids) {
    Platform pl;
    pl.name = platform_text(p, CL_PLATFORM_NAME);
    pl.vendor = platform_text(p, CL_PLATFORM_VENDOR);
    pl.version = platform_text(p, CL_PLATFORM_VERSION);
    for (cl_device_id d : device_ids(p)) {
      Device dv;
      dv.name = device_text(d, CL_DEVICE_NAME);
      dv.version = device_text(d, CL_DEVICE_VERSION);
      dv.c_version = device_text(d, CL_DEVICE_OPENCL_C_VERSION);
      cl_device_type type = 0;
      clGetDeviceInfo(d, CL_DEVICE_TYPE, sizeof type, &type, nullptr);
      dv.type = (type & CL_DEVICE_TYPE_GPU)           ? "gpu"
                : (type & CL_DEVICE_TYPE_CPU)         ? "cpu"
                : (type & CL_DEVICE_TYPE_ACCELERATOR) ? "accelerator"
                                                      : "other";
      cl_uint units = 0;
      clGetDeviceInfo(d, CL_DEVICE_MAX_COMPUTE_UNITS, sizeof units, &units, nullptr);
      dv.compute_units = units;
      cl_ulong memory = 0;
      clGetDeviceInfo(d, CL_DEVICE_GLOBAL_MEM_SIZE, sizeof memory, &memory, nullptr);
      dv.global_memory = memory;
      cl_ulong largest = 0;
      clGetDeviceInfo(d, CL_DEVICE_MAX_MEM_ALLOC_SIZE, sizeof largest, &largest, nullptr);
      dv.largest_buffer = largest;
      pl.devices.push_back(dv);
    }
    out.push_back(std::move(pl));
  }
  return out;
}

bool parse_device_choice(const std::string& text, DeviceChoice* out, std::string* problem) {
  const size_t colon = text.find(':');
  auto number = [](const std::string& t, size_t* v) {
    if (t.empty() || t.size() > 6) return false;
    for (char c : t)
      if (c < '0' || c > '9') return false;
    *v = static_cast<size_t>(std::stoul(t));
    return true;
  };
  if (colon == std::string::npos || !number(text.substr(0, colon), &out->platform) ||
      !number(text.substr(colon + 1), &out->device)) {
    *problem = "'" + text + "' is not PLATFORM:DEVICE (two numbers from grains devices, e.g. 0:0)";
    return false;
  }
  return true;
}

std::string choice_problem(const std::vector<Platform>& list, const DeviceChoice& choice) {
  if (choice.platform < list.size() && choice.device < list[choice.platform].devices.size())
    return "";
  std::string there;
  for (size_t p = 0; p < list.size(); ++p) {
    if (!there.empty()) there += "; ";
    there += "platform " + std::to_string(p) + " (" + list[p].name + ") has " +
             std::to_string(list[p].devices.size()) + " device(s)";
  }
  return "no device " + std::to_string(choice.platform) + ":" + std::to_string(choice.device) +
         " (" + there + ")";
}

bool buffer_cap(uint64_t* bytes, std::string* problem) {
  *bytes = 0;
  const char* cap = std::getenv("GRAINS_OPENCL_MAX_BUFFER_MIB");
  if (!cap || !*cap) return true;
  char* end = nullptr;
  const long long v = std::strtoll(cap, &end, 10);
  if (*end != '\0' || v < 1 || v > (1ll << 30)) {
    *problem = std::string("GRAINS_OPENCL_MAX_BUFFER_MIB: '") + cap + "' is not a whole number of MiB from 1 to 2^30";
    return false;
  }
  *bytes = static_cast<uint64_t>(v) << 20;
  return true;
}

bool sweep_items(uint64_t* items, std::string* problem) {
  *items = 0;
  const char* text = std::getenv("GRAINS_OPENCL_SWEEP_ITEMS");
  if (!text || !*text) return true;
  char* end = nullptr;
  const long long v = std::strtoll(text, &end, 10);
  if (*end != '\0' || v < 1 || v > 1024) {
    *problem = std::string("GRAINS_OPENCL_SWEEP_ITEMS: '") + text +
               "' is not a whole number from 1 to 1024";
    return false;
  }
  *items = static_cast<uint64_t>(v);
  return true;
}

namespace {

// an environment variable that is 0, 1 or unset (0)
bool switch_variable(const char* name, bool* on, std::string* problem) {
  *on = false;
  const char* text = std::getenv(name);
  if (!text || !*text) return true;
  const std::string value = text;
  if (value != "0" && value != "1") {
    *problem = std::string(name) + ": '" + value + "' is neither 0 nor 1";
    return false;
  }
  *on = value == "1";
  return true;
}

}  // namespace

bool host_contacts(bool* host, std::string* problem) {
  return switch_variable("GRAINS_OPENCL_HOST_CONTACTS", host, problem);
}

bool host_sleep(bool* host, std::string* problem) {
  return switch_variable("GRAINS_OPENCL_HOST_SLEEP", host, problem);
}

bool no_fp64(bool* off, std::string* problem) {
  return switch_variable("GRAINS_OPENCL_NO_FP64", off, problem);
}

bool chosen_device(DeviceChoice* out, std::string* problem) {
  *out = DeviceChoice{};
  uint64_t cap = 0, items = 0;
  bool host = false, sleep = false, fp32 = false;
  if (!buffer_cap(&cap, problem) || !sweep_items(&items, problem) ||
      !host_contacts(&host, problem) || !host_sleep(&sleep, problem) || !no_fp64(&fp32, problem))
    return false;
  const char* env = std::getenv("GRAINS_OPENCL_DEVICE");
  const std::string text = env ? env : "";
  if (!text.empty() && !parse_device_choice(text, out, problem)) {
    *problem = "GRAINS_OPENCL_DEVICE: " + *problem;
    return false;
  }
  const std::vector<Platform> list = platforms(problem);
  if (list.empty()) return false;
  if (std::string bad = choice_problem(list, *out); !bad.empty()) {
    *problem = (text.empty() ? "" : "GRAINS_OPENCL_DEVICE: ") + bad;
    return false;
  }
  return true;
}

cl_device_id device_id(size_t platform, size_t device, std::string* problem) {
  cl_int status = CL_SUCCESS;
  const std::vector<cl_platform_id> pids = platform_ids(&status);
  if (platform >= pids.size()) {
    *problem = "no platform " + std::to_string(platform);
    return nullptr;
  }
  const std::vector<cl_device_id> dids = device_ids(pids[platform]);
  if (device >= dids.size()) {
    *problem = "no device " + std::to_string(device) + " on platform " + std::to_string(platform);
    return nullptr;
  }
  return dids[device];
}

std::string program_text(const std::vector<SourceFile>& files, const std::string& main) {
  std::string out;
  expand(files, main, 0, &out);
  return out;
}

cl_program build_program(cl_context ctx, cl_device_id d, std::string* log) {
  return build_program(ctx, d, kernel_sources(), "grains.cl", log);
}

cl_program build_program(cl_context ctx, cl_device_id d, const std::vector<SourceFile>& files,
                         const std::string& main, std::string* log) {
  std::string main_text;
  try {
    main_text = program_text(files, main);
  } catch (const std::runtime_error& e) {
    *log = e.what();
    return nullptr;
  }
  const char* text = main_text.c_str();
  cl_int status = CL_SUCCESS;
  cl_program program = clCreateProgramWithSource(ctx, 1, &text, nullptr, &status);
  if (!program) {
    *log = "clCreateProgramWithSource failed (" + std::to_string(status) + ")";
    return nullptr;
  }
  std::string options = "-cl-std=CL1.2 -cl-fp32-correctly-rounded-divide-sqrt";
  // the program as a device without double precision has it (no_fp64; kernels/prelude.h,
  // GR_DOUBLES): the host's stages in place of those that need it, for testing them where every
  // device has it (a malformed value: refused by chosen_device, as no switch here)
  bool fp32 = false;
  std::string malformed;
  if (no_fp64(&fp32, &malformed) && fp32) options += " -D GR_NO_FP64";
  status = clBuildProgram(program, 1, &d, options.c_str(), nullptr, nullptr);
  size_t n = 0;
  clGetProgramBuildInfo(program, d, CL_PROGRAM_BUILD_LOG, 0, nullptr, &n);
  std::string text_log(n, '\0');
  if (n > 0) clGetProgramBuildInfo(program, d, CL_PROGRAM_BUILD_LOG, n, text_log.data(), nullptr);
  while (!text_log.empty() && (text_log.back() == '\0' || text_log.back() == '\n')) text_log.pop_back();
  if (status != CL_SUCCESS) {
    *log = "clBuildProgram failed (" + std::to_string(status) + "):\n" + text_log;
    clReleaseProgram(program);
    return nullptr;
  }
  *log = text_log;
  return program;
}

BuildResult build_kernels(size_t platform, size_t device) {
  BuildResult r;
  cl_device_id d = device_id(platform, device, &r.log);
  if (!d) return r;
  cl_int status = CL_SUCCESS;
  cl_context ctx = clCreateContext(nullptr, 1, &d, nullptr, nullptr, &status);
  if (!ctx) {
    r.log = "clCreateContext failed (" + std::to_string(status) + ")";
    return r;
  }
  const auto start = std::chrono::steady_clock::now();
  cl_program program = build_program(ctx, d, &r.log);
  r.ok = program != nullptr;
  if (program) clReleaseProgram(program);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  clReleaseContext(ctx);
  return r;
}

}  // namespace grains::opencl
