// The grains program: run | validate | nodes | cook | render | heap (DESIGN §5). Benchmarks and
// validation are a separate program, grains-lab (lab/).
#include "app/cli.h"

int main(int argc, char** argv) {
  return grains::cli_main(argc, argv);
}
