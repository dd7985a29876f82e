#pragma once

namespace grains {
// Parses the command line and runs the command; returns the process exit code
// (0 success, 2 bad input, 1 failure while running).
int cli_main(int argc, char** argv);
}  // namespace grains
