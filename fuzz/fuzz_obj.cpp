// libFuzzer target: the OBJ reader (engine/geometry_io.h) on bytes written to a temporary file.
// GeometryError is the documented answer to a bad file; anything else is a finding.
#include <cstddef>
#include <cstdint>

#include "engine/geometry_io.h"
#include "fuzz/fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace grains;
  const std::string& path = grains_fuzz::write_input(data, size, ".obj");
  grains_fuzz::only_documented_errors<GeometryError>("fuzz_obj", [&] { (void)read_mesh(path); });
  return 0;
}
