// libFuzzer target: the OBJ reader (engine/geometry_io.h) on bytes written to a temporary file.
// GeometryError is the documented answer to a bad file; anything else is a finding.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>

#include "engine/geometry_io.h"
#include "fuzz/input_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace grains;
  const std::string& path = grains_fuzz::write_input(data, size, ".obj");
  try {
    Mesh m = read_mesh(path);
    (void)m;
  } catch (const GeometryError&) {
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_obj: unexpected exception: %s\n", e.what());
    std::abort();
  }
  return 0;
}
