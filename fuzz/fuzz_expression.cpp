// libFuzzer target: compile a parameter expression from bytes and evaluate it, as a graph's
// string parameter is (engine/expression.h). ExprError is the documented answer to bad text;
// anything else that escapes (another exception, a crash, a sanitizer report) is a finding.
#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "engine/expression.h"
#include "fuzz/fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace grains;
  const std::string text(reinterpret_cast<const char*>(data), size);
  // the channel names a vector parameter gives its node (readable as previous values)
  static const std::vector<std::string> names = {"scale", "forcex", "forcey", "forcez"};
  const std::map<std::string, double> previous = {{"forcey", -9.81}, {"scale", 2}};
  grains_fuzz::only_documented_errors<ExprError>("fuzz_expression", [&] {
    Expression e(text, names);
    ExprVars v;
    v.TIMESTEP = 1.0 / 24;
    v.SFPS = 24;
    v.OBJNAME = "sand";
    v.DOPNET = "fuzz";
    v.channels = &previous;
    (void)e.eval(v);
    // a later substep of another object: strcmp($OBJNAME, ...) is resolved again
    v.ST = 0.5;
    v.SF = 12;
    v.T = 0.5;
    v.F = 13;
    v.OBJ = 1;
    v.OBJNAME = "other \"quoted\" name";
    v.DOPNET = "";
    (void)e.eval(v);
  });
  return 0;
}
