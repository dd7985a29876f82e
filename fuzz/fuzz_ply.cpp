// libFuzzer target: the PLY readers (engine/geometry_io.h) on bytes written to a temporary file:
// read_ply (points, attributes, edges) and read_mesh (a .ply as a collider/target mesh).
// GeometryError is the documented answer to a bad file; anything else is a finding.
#include <cstddef>
#include <cstdint>

#include "engine/geometry_io.h"
#include "fuzz/fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace grains;
  const std::string& path = grains_fuzz::write_input(data, size, ".ply");
  grains_fuzz::only_documented_errors<GeometryError>("fuzz_ply: read_ply",
                                                     [&] { (void)read_ply(path); });
  grains_fuzz::only_documented_errors<GeometryError>("fuzz_ply: read_mesh",
                                                     [&] { (void)read_mesh(path); });
  return 0;
}
