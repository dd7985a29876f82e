// `grains-lab laws` (lab/validation.h): validation.csv with its documented header and one row per
// law, the Markdown report, and exit code 2 for missing scenes. The physics is judged by the
// other tests in this folder; this one runs the collapse cases at 1 substep x 5 iterations,
// which is cheap and enough for the plumbing.
#include <catch2/catch.hpp>
#include <sstream>

#include "lab/source.h"
#include "lab/validation.h"
#include "tests/support/support.h"

using namespace grains;
using namespace grains::test;

TEST_CASE("laws writes validation.csv and the Markdown report", "[validation][lab]") {
  std::string dir = temp_dir("laws");
  std::string md = dir + "/V.md";
  REQUIRE(run_lab("laws --quick --only collapse --substeps 1 --iterations 5 --scenes " +
                      source_dir() + "/bench/validation --out " + dir + " --md " + md,
                  dir + "/log") == 0);
  std::stringstream csv(read_text(dir + "/validation.csv"));
  std::string line;
  std::getline(csv, line);
  CHECK(line == validation_csv_header());
  int rows = 0;
  while (std::getline(csv, line))
    if (!line.empty()) ++rows;
  // two sources per aspect ratio, and the exponent above a = 1.7
  CHECK(rows == 2 * static_cast<int>(validation_plan(true).aspects.size()) + 1);
  std::string report = read_text(md);
  CHECK_THAT(report,
             Catch::Contains(
                 "| law | source | expected | ours | difference | grains | settings | wall s |"));
  CHECK_THAT(report, Catch::Contains("Lube et al. 2004"));
  CHECK_THAT(report, Catch::Contains("### Column collapse, 1x5"));
  // the commit CMake stamped when the lab was built (lab/source.h); the lab never runs git
  CHECK_THAT(report, Catch::Contains("- **Source:** commit `" +
                                     std::string(lab::source_commit().id) + "`"));
}

TEST_CASE("laws exits with 2 when a scene is missing", "[validation][lab]") {
  std::string dir = temp_dir("laws_bad");
  CHECK(run_lab("laws --quick --scenes " + dir + "/nowhere --out " + dir + " --md " + dir + "/V.md",
                dir + "/log") == 2);
  CHECK_THAT(read_text(dir + "/log"), Catch::Contains("nowhere"));
}
