#include "lab/source.h"

#include "source_commit.h"  // generated in the build folder

namespace grains::lab {

SourceCommit source_commit() {
  return {GRAINS_SOURCE_COMMIT, GRAINS_SOURCE_DIRTY != 0};
}

}  // namespace grains::lab
