// The grains program: run | validate | nodes | cook | render | bench | laws (DESIGN §5).
#include "app/cli.h"

int main(int argc, char** argv) { return grains::cli_main(argc, argv); }
