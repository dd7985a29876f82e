// The grains OpenCL program's text (opencl::program_text): one text with every kernel header in
// place, #line directives naming where each line came from, built without an include path.
#include <catch2/catch.hpp>
#include <string>
#include <vector>

#include "nodes/grains/opencl/cl_program.h"
#include "nodes/grains/opencl/sources.h"

using namespace grains::opencl;

TEST_CASE("use_opencl: the program is one text, its files in place and named by #line",
          "[opencl]") {
  // a.h is included twice (its guard keeps one copy), b.h from a.h and from a branch the
  // compiler may skip; an include of a file that is not one of them stays as it is
  const std::vector<SourceFile> files = {
      {"main.cl",
       "#include \"a.h\"\n#if defined(X)\n#include \"b.h\"\n#else\n#include "
       "\"other/c.h\"\n#endif\n  # include \"a.h\"\nint m;\n"},
      {"a.h", "#ifndef A\n#define A\n#include \"b.h\"\nint a;\n#endif\n"},
      {"b.h", "#ifndef B\n#define B\nint b;\n#endif\n"}};
  const std::string b_text = "#line 1 \"b.h\"\n#ifndef B\n#define B\nint b;\n#endif\n";
  const std::string a_text =
      "#line 1 \"a.h\"\n#ifndef A\n#define A\n" + b_text + "#line 4 \"a.h\"\nint a;\n#endif\n";
  const std::string expected = "#line 1 \"main.cl\"\n" + a_text + "#line 2 \"main.cl\"\n" +
                               "#if defined(X)\n" + b_text + "#line 4 \"main.cl\"\n" +
                               "#else\n#include \"other/c.h\"\n#endif\n" + a_text +
                               "#line 8 \"main.cl\"\nint m;\n";
  CHECK(program_text(files, "main.cl") == expected);
  CHECK_THROWS(program_text(files, "missing.cl"));

  // the grains program: every embedded file it includes is in its text (no include path is
  // given), and the text is the same every time (a driver's cache of built programs finds it)
  const std::string grains = program_text(kernel_sources(), "grains.cl");
  for (const SourceFile& f : kernel_sources()) {
    INFO(f.name);
    CHECK(grains.find("#include \"" + std::string(f.name) + "\"") == std::string::npos);
  }
  CHECK(grains.find("#line 1 \"contact.h\"") != std::string::npos);
  CHECK(grains == program_text(kernel_sources(), "grains.cl"));
}

TEST_CASE(
    "use_opencl: a program that does not build gives the compiler's log, naming the file and line",
    "[opencl]") {
  std::string problem;
  cl_device_id d = device_id(0, 0, &problem);
  REQUIRE(d);
  cl_int status = CL_SUCCESS;
  cl_context ctx = clCreateContext(nullptr, 1, &d, nullptr, nullptr, &status);
  REQUIRE(ctx);
  const std::vector<SourceFile> files = {
      {"main.cl", "#include \"bad.h\"\n__kernel void k(__global int* x) { x[0] = y; }\n"},
      {"bad.h", "/* line 1 */\nint y = ;\n"}};
  std::string log;
  cl_program program = build_program(ctx, d, files, "main.cl", &log);
  CHECK(program == nullptr);
  INFO(log);
  CHECK(log.rfind("clBuildProgram failed", 0) == 0);
  CHECK(log.find("bad.h:2") != std::string::npos);
  // and the grains program builds from its one text
  cl_program grains = build_program(ctx, d, &log);
  CHECK(grains != nullptr);
  if (grains) clReleaseProgram(grains);
  clReleaseContext(ctx);
}
