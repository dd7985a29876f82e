#include "app/cli.h"

namespace grains {
int cli_main(int, char**) { return 1; }
}  // namespace grains
