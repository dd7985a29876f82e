// Graph loading and validation (DESIGN §2): every bad input is refused before the first frame,
// naming the file, the JSON pointer and what is wrong.
#include <catch2/catch.hpp>

#include "tests/support/support.h"

using namespace grains;
using grains::test::graph_from;

namespace {

// A valid graph; cases below break one thing at a time.
const char* kGood = R"({
  "grains_graph": 1, "name": "g", "fps": 24, "frames": 2, "seed": 1,
  "nodes": [
    {"name": "sand", "type": "source", "params": {"shape": "box", "size": [0.2, 0.2, 0.2], "separation": 0.1}},
    {"name": "gravity", "type": "force", "inputs": ["sand"], "params": {"force": [0, -9.81, 0]}},
    {"name": "ground", "type": "collider", "params": {"shape": "plane"}},
    {"name": "solver", "type": "solver", "inputs": ["gravity"], "params": {"substeps": 2, "colliders": ["ground"]}}
  ]
})";

std::string replace(std::string s, const std::string& from, const std::string& to) {
  auto at = s.find(from);
  REQUIRE(at != std::string::npos);
  return s.replace(at, from.size(), to);
}

// Loads `text` and returns the error; fails the test if it loads.
LoadError error_of(const std::string& text) { return test::refusal_of(text, "bad.json"); }

void check_error(const std::string& text, const std::string& pointer, const std::string& words) {
  LoadError e = error_of(text);
  INFO(e.what());
  CHECK(e.file == "bad.json");
  CHECK(e.pointer == pointer);
  CHECK_THAT(e.message, Catch::Contains(words));
  CHECK_THAT(std::string(e.what()), Catch::StartsWith("bad.json: "));
}

}  // namespace

TEST_CASE("a good graph loads", "[graph]") {
  Graph g = graph_from(kGood);
  CHECK(g.nodes.size() == 4);
  CHECK(g.solvers == std::vector<int>{3});
  CHECK(g.fps == 24);
  CHECK(g.frames == 2);
  CHECK(g.nodes[1].inputs == std::vector<int>{0});
}

TEST_CASE("malformed JSON", "[graph][bad]") {
  check_error(replace(kGood, "\"frames\": 2,", "\"frames\": 2,,"), "", "malformed JSON");
}

TEST_CASE("wrong grains_graph version", "[graph][bad]") {
  check_error(replace(kGood, "\"grains_graph\": 1", "\"grains_graph\": 2"), "/grains_graph",
              "unsupported version");
}

TEST_CASE("missing grains_graph", "[graph][bad]") {
  check_error(replace(kGood, "\"grains_graph\": 1,", ""), "/grains_graph", "not a grains graph");
}

TEST_CASE("fps out of its range: zero, negative, a frame of over 1000 s or under 1 us",
          "[graph][bad]") {
  for (const char* fps : {"0", "-24", "1e-300", "0.0009", "1e308", "1000001"})
    check_error(replace(kGood, "\"fps\": 24", std::string("\"fps\": ") + fps), "/fps",
                "fps must lie between 0.001 and 1000000.0, got ");
  for (const char* fps : {"0.001", "1e6"})
    CHECK_NOTHROW(graph_from(replace(kGood, "\"fps\": 24", std::string("\"fps\": ") + fps)));
}

TEST_CASE("zero or negative frames", "[graph][bad]") {
  check_error(replace(kGood, "\"frames\": 2", "\"frames\": 0"), "/frames", "at least 1");
  check_error(replace(kGood, "\"frames\": 2", "\"frames\": -3"), "/frames", "at least 1");
  check_error(replace(kGood, "\"frames\": 2", "\"frames\": 2.5"), "/frames", "integer");
}

TEST_CASE("zero or negative separation", "[graph][bad]") {
  check_error(replace(kGood, "\"separation\": 0.1", "\"separation\": 0"),
              "/nodes/0/params/separation", "greater than 0");
  check_error(replace(kGood, "\"separation\": 0.1", "\"separation\": -0.1"),
              "/nodes/0/params/separation", "greater than 0");
}

TEST_CASE("unknown node type", "[graph][bad]") {
  check_error(replace(kGood, "\"type\": \"force\"", "\"type\": \"forse\""), "/nodes/1/type",
              "unknown node type 'forse'");
}

TEST_CASE("unknown parameter", "[graph][bad]") {
  check_error(replace(kGood, "\"force\": [0, -9.81, 0]", "\"forse\": [0, -9.81, 0]"),
              "/nodes/1/params/forse", "unknown parameter 'forse'");
}

TEST_CASE("wrong value types", "[graph][bad]") {
  // a string where a vector is expected
  check_error(replace(kGood, "\"force\": [0, -9.81, 0]", "\"force\": \"down\""),
              "/nodes/1/params/force", "vector of 3 components");
  // a vector of the wrong length
  check_error(replace(kGood, "\"force\": [0, -9.81, 0]", "\"force\": [0, -9.81]"),
              "/nodes/1/params/force", "2 components");
  // a number where a string is expected
  check_error(replace(kGood, "\"shape\": \"box\"", "\"shape\": 3"), "/nodes/0/params/shape",
              "is a string");
  // a menu value that is not a choice
  check_error(replace(kGood, "\"shape\": \"box\"", "\"shape\": \"cone\""), "/nodes/0/params/shape",
              "must be one of");
  // a boolean where a number is expected
  check_error(replace(kGood, "\"separation\": 0.1", "\"separation\": true"),
              "/nodes/0/params/separation", "got a boolean");
  // a fraction where an integer is expected
  check_error(replace(kGood, "\"substeps\": 2", "\"substeps\": 2.5"), "/nodes/3/params/substeps",
              "integer");
  // colliders must be names
  check_error(replace(kGood, "\"colliders\": [\"ground\"]", "\"colliders\": [1]"),
              "/nodes/3/params/colliders/0", "expected a string");
}

TEST_CASE("dangling input", "[graph][bad]") {
  check_error(replace(kGood, "\"inputs\": [\"sand\"]", "\"inputs\": [\"sandd\"]"),
              "/nodes/1/inputs/0", "names no node");
}

TEST_CASE("collider names no collider", "[graph][bad]") {
  check_error(replace(kGood, "\"colliders\": [\"ground\"]", "\"colliders\": [\"grund\"]"),
              "/nodes/3/params/colliders/0", "names no node");
  check_error(replace(kGood, "\"colliders\": [\"ground\"]", "\"colliders\": [\"sand\"]"),
              "/nodes/3/params/colliders/0", "not a collider");
}

TEST_CASE("cycles", "[graph][bad]") {
  std::string g = replace(kGood, "{\"name\": \"sand\", \"type\": \"source\",",
                          "{\"name\": \"sand\", \"type\": \"source\", \"inputs\": [\"gravity\"],");
  LoadError e = error_of(g);
  CHECK_THAT(e.message, Catch::Contains("cycle"));
  CHECK_THAT(e.pointer, Catch::StartsWith("/nodes/"));
  CHECK_THAT(e.pointer, Catch::EndsWith("/inputs/0"));
}

TEST_CASE("a chain that reaches no solver", "[graph][bad]") {
  std::string g = replace(kGood, "{\"name\": \"ground\"",
                          "{\"name\": \"lost\", \"type\": \"force\", \"inputs\": [\"sand\"]},\n"
                          "    {\"name\": \"ground\"");
  check_error(g, "/nodes/2", "reaches a solver");
}

TEST_CASE("no solver at all", "[graph][bad]") {
  const char* g = R"({"grains_graph": 1, "nodes": [
    {"name": "sand", "type": "source"}]})";
  check_error(g, "/nodes/0", "reaches a solver");
}

TEST_CASE("expressions that do not parse", "[graph][bad]") {
  check_error(replace(kGood, "\"force\": [0, -9.81, 0]", "\"force\": [0, \"-9.81 * (\", 0]"),
              "/nodes/1/params/force/1", "does not parse");
  check_error(replace(kGood, "\"substeps\": 2", "\"substeps\": \"$NOSUCHVAR + 1\""),
              "/nodes/3/params/substeps", "does not parse");
}

TEST_CASE("keyframes are checked", "[graph][bad]") {
  check_error(replace(kGood, "\"force\": [0, -9.81, 0]",
                      "\"force\": [0, {\"keys\": [[1, 0], [0.5, 1]]}, 0]"),
              "/nodes/1/params/force/1/keys/1", "increase strictly");
  check_error(replace(kGood, "\"force\": [0, -9.81, 0]",
                      "\"force\": [0, {\"keys\": [[0, 0]], \"interp\": \"bezier\"}, 0]"),
              "/nodes/1/params/force/1/interp", "linear");
}

TEST_CASE("unknown fields and duplicate names", "[graph][bad]") {
  check_error(replace(kGood, "\"seed\": 1,", "\"seed\": 1, \"fsp\": 3,"), "/fsp", "unknown field");
  check_error(replace(kGood, "\"name\": \"gravity\"", "\"name\": \"sand\""), "/nodes/1/name",
              "duplicate node name");
}

TEST_CASE("a source file that does not exist", "[graph][bad]") {
  check_error(replace(kGood, "\"shape\": \"box\"", "\"shape\": \"file\", \"file\": \"nope.ply\""),
              "/nodes/0/params/file", "file not found");
}

TEST_CASE("set overrides are validated like the file", "[graph]") {
  register_builtin_nodes();
  Graph g = parse_graph(kGood, "g.json", {parse_override("solver.substeps=5")});
  CHECK(g.nodes[3].params.at("substeps").channels[0].value == 5);
  CHECK_THROWS_AS(parse_graph(kGood, "g.json", {parse_override("solver.substeps=0")}), LoadError);
  CHECK_THROWS_AS(parse_graph(kGood, "g.json", {parse_override("nobody.substeps=3")}), LoadError);
  CHECK_THROWS_AS(parse_override("solver-substeps"), LoadError);
}
