// `grains devices`: the OpenCL platforms and devices the loader finds, each device building the
// grains kernels from the sources embedded in the program; and the refusal when there is none.
#include <catch2/catch.hpp>
#include <stdlib.h>

#include <filesystem>

#include "tests/support/support.h"

using namespace grains;

TEST_CASE("grains devices lists PoCL's CPU device, which builds the grains kernels", "[cli][opencl]") {
  // scripts/install-deps.sh installs PoCL (pocl-opencl-icd), so every machine that runs the
  // tests has at least its CPU device; the build compiles grains.cl and every kernel header
  const std::string dir = test::temp_dir("devices");
  const std::string log = dir + "/devices.txt";
  REQUIRE(test::run_grains("devices", log) == 0);
  const std::string out = test::read_text(log);
  INFO(out);
  CHECK_THAT(out, Catch::Contains("platform 0: Portable Computing Language"));
  CHECK_THAT(out, Catch::Contains("device 0: "));
  CHECK_THAT(out, Catch::Contains("(cpu, "));
  // the most one buffer may hold (docs/opencl.md, "Memory"): PoCL gives a positive figure
  CHECK_THAT(out, Catch::Contains(" MiB, largest buffer "));
  CHECK_THAT(out, !Catch::Contains("largest buffer 0 MiB"));
  CHECK_THAT(out, Catch::Contains("grains kernels: built in"));
  CHECK_THAT(out, !Catch::Contains("build failed"));
}

TEST_CASE("grains devices without an OpenCL platform says so and exits 2", "[cli][opencl][bad]") {
  // the ICD loader reads its drivers from OCL_ICD_VENDORS when set: an empty folder is a
  // machine with no OpenCL driver installed
  const std::string dir = test::temp_dir("devices_none");
  std::filesystem::create_directories(dir + "/vendors");
  const char* before = getenv("OCL_ICD_VENDORS");
  const std::string saved = before ? before : "";
  setenv("OCL_ICD_VENDORS", (dir + "/vendors").c_str(), 1);
  const int rc = test::run_grains("devices", dir + "/log.txt");
  if (before) setenv("OCL_ICD_VENDORS", saved.c_str(), 1);
  else unsetenv("OCL_ICD_VENDORS");
  const std::string out = test::read_text(dir + "/log.txt");
  INFO(out);
  CHECK(rc == 2);
  CHECK_THAT(out, Catch::Contains("grains devices: no OpenCL platform found"));
  CHECK_THAT(out, Catch::Contains("pocl-opencl-icd"));
}

TEST_CASE("grains devices builds on the one device chosen, and refuses a choice that names none",
          "[cli][opencl][bad]") {
  // --device P:D, else the environment variable GRAINS_OPENCL_DEVICE: 0:0 is PoCL's CPU
  const std::string dir = test::temp_dir("devices_choice");
  const std::string log = dir + "/log.txt";
  REQUIRE(test::run_grains("devices --device 0:0", log) == 0);
  CHECK_THAT(test::read_text(log), Catch::Contains("grains kernels: built in"));
  CHECK(test::run_grains("devices --device 7:0", log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("grains devices: --device: no device 7:0 (platform 0"));
  CHECK(test::run_grains("devices --device gpu", log) == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("'gpu' is not PLATFORM:DEVICE"));
  setenv("GRAINS_OPENCL_DEVICE", "0:9", 1);
  const int rc = test::run_grains("devices", log);
  unsetenv("GRAINS_OPENCL_DEVICE");
  CHECK(rc == 2);
  CHECK_THAT(test::read_text(log), Catch::Contains("GRAINS_OPENCL_DEVICE: no device 0:9"));
}
