// The attribute node: per-point expressions that set or create attributes, with the point
// variables a Houdini user types, within a group, and refusals for what cannot be set.
#include <catch2/catch.hpp>
#include <cmath>

#include <nlohmann/json.hpp>

#include "tests/support/support.h"

using namespace grains;
using json = nlohmann::json;

namespace {

// A 4 x 1 x 3 grid of 12 grains at 0.1 m (x from -0.15, z from -0.1, y 0.5), emitted at frame
// 1, then `nodes` in a chain below it; no forces. Returns the points after `frames` frames.
ParticleStore after(const json& nodes, int frames = 1, const std::string& graph_dir = "") {
  json chain = json::array();
  chain.push_back({{"name", "src"},
                   {"type", "source"},
                   {"params",
                    {{"shape", "box"}, {"size", {0.4, 0.1, 0.3}}, {"center", {0, 0.5, 0}},
                     {"separation", 0.1}}}});
  std::string above = "src";
  for (json n : nodes) {
    n["inputs"] = {above};
    above = n["name"];
    chain.push_back(n);
  }
  chain.push_back({{"name", "solver"}, {"type", "solver"}, {"inputs", {above}}});
  json g = {{"grains_graph", 1}, {"fps", 24}, {"frames", frames}, {"seed", 1}, {"nodes", chain}};
  const std::string dir = graph_dir.empty() ? test::temp_dir("attribute") : graph_dir;
  Simulation sim(test::graph_from(g.dump(), dir + "/g.json"), 1);
  for (int f = 0; f < frames; ++f) sim.step_frame();
  return sim.object(0).pts;
}

json attribute(const std::string& name, const json& params) {
  return {{"name", name}, {"type", "attribute"}, {"params", params}};
}

}  // namespace

TEST_CASE("attribute sets a known attribute per point from its position and id", "[nodes][attribute]") {
  // friction = 2 x the grain's x + 1 and pscale = 0.01 + $ID / 1000: each grain's own
  ParticleStore s = after({attribute("fr", {{"attribute", "friction"}, {"value", "2 * $TX + 1"}}),
                           attribute("ps", {{"attribute", "pscale"}, {"value", "0.01 + $ID / 1000"}})});
  REQUIRE(s.size() == 12);
  const float* P = s.v3_if("P");
  const float* fr = s.f_if("friction");
  const float* ps = s.f_if("pscale");
  const int32_t* id = s.i_if("id");
  REQUIRE(fr);
  for (size_t k = 0; k < s.size(); ++k) {
    CHECK(fr[k] == Approx(2 * P[3 * k] + 1).margin(1e-6));
    CHECK(ps[k] == Approx(0.01 + id[k] / 1000.0).margin(1e-7));
  }
}

TEST_CASE("attribute creates float and vector attributes and reads others with @", "[nodes][attribute]") {
  // a new float `height` = y; a vector `dir` = (@height, $PT, $NPT); then `double` = 2 @height
  // and `dx` = @dir_y (the vector's y, the point number) after them in the chain; a vector `all`
  // from one expression, $PT in each component
  ParticleStore s = after({attribute("h", {{"attribute", "height"}, {"value", "$TY"}}),
                           attribute("d", {{"attribute", "dir"}, {"type", "vector"},
                                           {"value", "@height, $PT, if($NPT == 12, 1, 0)"}}),
                           attribute("x2", {{"attribute", "double"}, {"value", "2 * @height"}}),
                           attribute("dy", {{"attribute", "dx"}, {"value", "fit(@dir_y, 0, 11, 0, 1)"}}),
                           attribute("w", {{"attribute", "all"}, {"type", "vector"}, {"value", "$PT"}})});
  REQUIRE(s.has("height"));
  REQUIRE(s.find("dir")->components() == 3);
  const float* P = s.v3_if("P");
  const float* dir = s.v3_if("dir");
  for (size_t k = 0; k < s.size(); ++k) {
    CHECK(s.f_if("height")[k] == Approx(P[3 * k + 1]));
    CHECK(dir[3 * k] == Approx(P[3 * k + 1]));
    CHECK(dir[3 * k + 1] == Approx(double(k)));
    CHECK(dir[3 * k + 2] == 1.0f);
    CHECK(s.f_if("double")[k] == Approx(2 * P[3 * k + 1]));
    CHECK(s.f_if("dx")[k] == Approx(k / 11.0));
    for (int c = 0; c < 3; ++c) CHECK(s.v3_if("all")[3 * k + c] == Approx(double(k)));  // one for all
  }
}

TEST_CASE("attribute acts only on its group and sees time and age", "[nodes][attribute]") {
  // the grains with x > 0 (half of them) form a group; only they get targetstiffness = $F; every
  // grain's `older` = $AGE (the solver ages grains by a frame's 1/24 s each frame)
  ParticleStore s = after(
      {{{"name", "grp"}, {"type", "group"},
        {"params", {{"group_name", "right"}, {"rule", "box"}, {"center", {0.5, 0.5, 0}}, {"size", {1, 1, 1}}}}},
       attribute("ts", {{"attribute", "targetstiffness"}, {"value", "$F"}, {"group", "right"}}),
       attribute("a", {{"attribute", "older"}, {"value", "$AGE"}})},
      3);
  const float* P = s.v3_if("P");
  const float* ts = s.f_if("targetstiffness");
  REQUIRE(ts);
  int set = 0;
  for (size_t k = 0; k < s.size(); ++k) {
    if (P[3 * k] > 0) {
      CHECK(ts[k] == Approx(3));  // frame 3 (1-based, the frame being computed)
      ++set;
    } else {
      CHECK(ts[k] == 0.0f);  // the known default: no pin
    }
    CHECK(s.f_if("older")[k] == Approx(2.0 / 24).margin(1e-6));  // at frame 3's start
  }
  CHECK(set == 6);
}

TEST_CASE("attribute refuses what it cannot set, names the point of a non-finite value",
          "[nodes][attribute][bad]") {
  const std::string dir = test::temp_dir("attribute_bad");
  auto load_error = [&](const json& params) {
    try {
      after(json::array({attribute("a", params)}), 1, dir);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  CHECK_THAT(load_error({{"attribute", "id"}, {"value", "1"}}), Catch::Contains("kept by the engine"));
  CHECK_THAT(load_error({{"attribute", "2x"}, {"value", "1"}}), Catch::Contains("not an attribute name"));
  CHECK_THAT(load_error({{"attribute", "friction"}, {"value", "1 +"}}), Catch::Contains("value"));
  CHECK_THAT(load_error({{"attribute", "v"}, {"value", "1, 2"}}), Catch::Contains("three"));
  CHECK_THAT(load_error({{"attribute", "mass"}, {"value", "1, 2, 3"}}), Catch::Contains("float attribute takes one"));
  CHECK_THAT(load_error({{"attribute", "friction"}, {"value", "@nothing"}}),
             Catch::Contains("@nothing names no attribute"));
  const std::string nan = load_error({{"attribute", "friction"}, {"value", "sqrt(-1 - $ID)"}});
  CHECK_THAT(nan, Catch::Contains("node 'a': point id"));
  CHECK_THAT(nan, Catch::Contains("'friction' would be"));
}
