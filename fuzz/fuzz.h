// What the fuzz targets share: each accepts only its reader's documented error, and the readers
// that take a path get the input through a temporary file.
#pragma once
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <string>

namespace grains_fuzz {

// Runs f. The documented error (Documented) is the right answer to bad bytes; any other
// exception is a finding: printed with `what`, then abort() so that libFuzzer keeps the input.
template <class Documented, class F>
void only_documented_errors(const char* what, F&& f) {
  try {
    f();
  } catch (const Documented&) {
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: unexpected exception: %s\n", what, e.what());
    std::abort();
  }
}

// A file named NAME.EXT in /dev/shm (memory) when it exists, else the temporary folder; one per
// process, so parallel fuzzing jobs do not share it. Rewritten on every call.
inline const std::string& write_input(const uint8_t* data, size_t size, const char* ext) {
  static const std::string path = [ext] {
    std::filesystem::path dir = std::filesystem::is_directory("/dev/shm")
                                    ? std::filesystem::path("/dev/shm")
                                    : std::filesystem::temp_directory_path();
    return (dir / ("grains-fuzz-" + std::to_string(getpid()) + ext)).string();
  }();
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || (size > 0 && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) {
    std::perror(path.c_str());
    std::abort();
  }
  return path;
}

}  // namespace grains_fuzz
