// The commit `grains-lab` was built from, so that a report can be traced to its code. CMake
// stamps it at build time (cmake/source_commit.cmake); the program never runs git.
#pragma once

namespace grains::lab {

struct SourceCommit {
  const char* id;  // `git rev-parse --short HEAD` at build time; "unknown" outside a git checkout
  bool dirty;      // engine/, nodes/, lab/, cli/, viewer-offline/ or CMakeLists.txt differed
                   // from that commit when the program was built
};
SourceCommit source_commit();

}  // namespace grains::lab
