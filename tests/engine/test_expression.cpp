#include <catch2/catch.hpp>

#include <cmath>
#include <map>
#include <numbers>
#include <string>
#include <vector>

#include "engine/expression.h"

using namespace grains;

namespace {

double eval1(const std::string& text, const ExprVars& v = {},
             const std::vector<std::string>& channels = {}) {
  Expression e(text, channels);
  return e.eval(v);
}

}  // namespace

TEST_CASE("every local variable reads with and without $", "[expression]") {
  ExprVars v;
  v.ST = 1.5;
  v.SF = 36;
  v.T = 1.75;
  v.F = 37;
  v.TIMESTEP = 1.0 / 24;
  v.SFPS = 24;
  v.OBJ = 2;
  v.OBJID = 11;
  v.NOBJ = 3;
  v.SNOBJ = 5;
  v.OBJCT = 0.25;
  v.OBJCF = 6;
  v.DATACT = 0.5;
  v.DATACF = 12;
  const std::vector<std::pair<std::string, double>> expected = {
      {"ST", 1.5},   {"SF", 36},      {"T", 1.75},    {"F", 37},      {"TIMESTEP", 1.0 / 24},
      {"SFPS", 24},  {"OBJ", 2},      {"OBJID", 11},  {"NOBJ", 3},    {"SNOBJ", 5},
      {"OBJCT", 0.25}, {"OBJCF", 6}, {"DATACT", 0.5}, {"DATACF", 12}, {"FF", 37}};
  for (const auto& [name, value] : expected) {
    INFO(name);
    CHECK(eval1("$" + name, v) == value);
    CHECK(eval1(name, v) == value);
  }
  // values are copied on each eval: a changed variable is seen by the same expression
  Expression e("$SF * 2 + F", {});
  CHECK(e.eval(v) == Approx(36 * 2 + 37));
  v.SF = 10;
  v.F = 11;
  CHECK(e.eval(v) == Approx(10 * 2 + 11));
}

TEST_CASE("fit maps the frame into 0..1 and clamps", "[expression]") {
  Expression e("fit($SF, 0, 48, 0, 1)", {});
  ExprVars v;
  const std::vector<std::pair<double, double>> cases = {
      {-10, 0}, {0, 0}, {12, 0.25}, {24, 0.5}, {36, 0.75}, {48, 1}, {100, 1}};
  for (const auto& [sf, want] : cases) {
    v.SF = sf;
    INFO("SF = " << sf);
    CHECK(e.eval(v) == Approx(want));
  }
  CHECK(eval1("fit01(0.25, 10, 20)") == Approx(12.5));
  CHECK(eval1("fit01(2, 10, 20)") == Approx(20));
  CHECK(eval1("fit(5, 10, 0, 0, 1)") == Approx(0.5));   // reversed old range
  CHECK(eval1("fit(20, 10, 0, 0, 1)") == Approx(0));   // clamped to newmin side
  CHECK(eval1("efit(96, 0, 48, 0, 1)") == Approx(2));  // unclamped
}

TEST_CASE("$ST < 1 toggles off after one second", "[expression]") {
  Expression e("$ST < 1", {});
  ExprVars v;
  for (double st : {0.0, 0.5, 0.999}) {
    v.ST = st;
    CHECK(e.eval(v) == 1);
  }
  for (double st : {1.0, 1.5, 10.0}) {
    v.ST = st;
    CHECK(e.eval(v) == 0);
  }
  CHECK(eval1("$ST < 1 ? 3 : 4") == 3);
  CHECK(eval1("if(ST > 1, 3, 4)") == 4);
}

TEST_CASE("a channel reads its own previous value", "[expression]") {
  Expression e("$activation * 0.5 + rate", {"activation", "rate"});
  ExprVars v;
  // no channels map: every channel reads 0
  CHECK(e.eval(v) == 0);
  std::map<std::string, double> prev = {{"activation", 4.0}, {"rate", 1.0}};
  v.channels = &prev;
  CHECK(e.eval(v) == Approx(3.0));
  prev["activation"] = 3.0;
  CHECK(e.eval(v) == Approx(2.5));
  // a channel missing from the map reads 0
  prev.erase("rate");
  CHECK(e.eval(v) == Approx(1.5));
  CHECK(eval1("activation", v, {"activation"}) == 3.0);
  // a channel name not given to the constructor is unknown
  CHECK_THROWS_AS(Expression("$other", {"activation"}), ExprError);
}

TEST_CASE("ch(\"name\") reads the node's own channel as Houdini users type it", "[expression]") {
  // the same previous values as the bare channel names; a vector's components are NAMEx..z
  Expression e("ch(\"activation\") * 0.5 + ch( \"forcey\" )", {"activation", "forcex", "forcey", "forcez"});
  std::map<std::string, double> prev = {{"activation", 4.0}, {"forcey", -9.81}};
  ExprVars v;
  v.channels = &prev;
  CHECK(e.eval(v) == Approx(2.0 - 9.81));
  // inside a strcmp literal it is text, not a call
  CHECK(eval1("strcmp(\"ch(x)\", \"ch(x)\")") == 0);
  // a name the node does not have is refused with the names it has
  try {
    Expression bad("ch(\"drag\") + 1", {"activation", "rate"});
    FAIL("no error");
  } catch (const ExprError& err) {
    CHECK_THAT(err.what(), Catch::Contains("ch(\"drag\"): the node has no channel 'drag' (its channels: activation, rate)"));
  }
  CHECK_THROWS_AS(Expression("ch(activation)", {"activation"}), ExprError);
  CHECK_THROWS_AS(Expression("ch(\"activation\"", {"activation"}), ExprError);
}

TEST_CASE("strcmp compares the object's strings", "[expression]") {
  Expression e("strcmp($OBJNAME, \"sand\") == 0", {});
  ExprVars v;
  v.OBJNAME = "sand";
  CHECK(e.eval(v) == 1);
  v.OBJNAME = "rock";
  CHECK(e.eval(v) == 0);
  v.OBJNAME = "sand";
  CHECK(e.eval(v) == 1);
  v.OBJNAME = "";
  CHECK(e.eval(v) == 0);

  // C-like sign, both argument orders, without $ and with DOPNET
  ExprVars w;
  w.OBJNAME = "b";
  w.DOPNET = "sandpile";
  CHECK(eval1("strcmp(OBJNAME, \"a\")", w) == 1);
  CHECK(eval1("strcmp(\"a\", $OBJNAME)", w) == -1);
  CHECK(eval1("strcmp($DOPNET, \"sandpile\")", w) == 0);
  CHECK(eval1("strcmp(\"x\", \"x\") + strcmp($OBJNAME, $DOPNET) * 10", w) == -10);
  CHECK(eval1("strcmp( $OBJNAME , \"b\" ) == 0 ? $ST + 5 : 0", w) == 5);

  // string arguments other than literals and the two string variables are errors
  CHECK_THROWS_AS(Expression("strcmp($OBJNAME, 3)", {}), ExprError);
  CHECK_THROWS_AS(Expression("strcmp($OBJNAME, \"sand)", {}), ExprError);
}

TEST_CASE("strcmp reads the help page's other string variables", "[expression]") {
  // ALLOBJIDS / ALLOBJNAMES list the objects the node processes; the REL* variables are set only
  // when data is attached to a relationship, which no node here does: empty strings
  ExprVars v;
  v.ALLOBJIDS = "0 1";
  v.ALLOBJNAMES = "left right";
  CHECK(eval1("strcmp($ALLOBJIDS, \"0 1\")", v) == 0);
  CHECK(eval1("strcmp(ALLOBJNAMES, \"left right\")", v) == 0);
  for (const char* rel : {"RELNAME", "RELOBJIDS", "RELOBJNAMES", "RELAFFOBJIDS", "RELAFFOBJNAMES"}) {
    INFO(rel);
    CHECK(eval1(std::string("strcmp($") + rel + ", \"\")", v) == 0);
  }
  // a changed list is seen by the same compiled expression
  Expression e("strcmp($ALLOBJNAMES, \"sand\") == 0", {});
  v.ALLOBJNAMES = "sand";
  CHECK(e.eval(v) == 1);
  v.ALLOBJNAMES = "sand rock";
  CHECK(e.eval(v) == 0);
  // an unknown name is refused with the names strcmp takes
  try {
    Expression bad("strcmp($OBJNAMES, \"a\")", {});
    FAIL("no error");
  } catch (const ExprError& err) {
    CHECK_THAT(err.what(), Catch::Contains("$ALLOBJNAMES"));
  }
}

TEST_CASE("a parse error throws ExprError naming the expression", "[expression]") {
  const std::string bad = "fit($SF, 0, 48, 0";
  try {
    Expression e(bad, {});
    FAIL("no exception");
  } catch (const ExprError& err) {
    CHECK(std::string(err.what()).find(bad) != std::string::npos);
  }
  for (const char* text : {"$NOPE + 1", "1 +", "sin(", "$OBJNAME"}) {
    INFO(text);
    try {
      Expression e(text, {});
      FAIL("no exception");
    } catch (const ExprError& err) {
      CHECK(std::string(err.what()).find(text) != std::string::npos);
    }
  }
  CHECK_THROWS_AS(Channel::expression("2 **", {}), ExprError);
}

TEST_CASE("added functions", "[expression]") {
  CHECK(eval1("deg(_pi)") == Approx(180));
  CHECK(eval1("rad(90)") == Approx(std::numbers::pi / 2));
  CHECK(eval1("sin(rad(90))") == Approx(1));  // trig stays in radians
  CHECK(eval1("floor(-1.5)") == -2);
  CHECK(eval1("ceil(1.2)") == 2);
  CHECK(eval1("round(2.5)") == 3);
  CHECK(eval1("round(-2.5)") == -3);
  CHECK(eval1("clamp(5, 0, 1)") == 1);
  CHECK(eval1("clamp(-5, 0, 1)") == 0);
  CHECK(eval1("clamp(0.3, 0, 1)") == Approx(0.3));
  CHECK(eval1("smooth(0.5, 0, 1)") == Approx(0.5));
  CHECK(eval1("smooth(-1, 0, 1)") == 0);
  CHECK(eval1("smooth(2, 0, 1)") == 1);
  CHECK(eval1("min(3, 2)") == 2);
  CHECK(eval1("max(3, 2)") == 3);
}

TEST_CASE("rand is deterministic and in 0..1", "[expression]") {
  Expression e("rand($SF)", {});
  ExprVars v;
  double sum = 0;
  int distinct_from_prev = 0;
  double prev = -1;
  for (int i = 0; i < 1000; ++i) {
    v.SF = i * 0.37 - 50;
    const double r = e.eval(v);
    CHECK(r >= 0);
    CHECK(r < 1);
    CHECK(r == e.eval(v));                         // same seed, same value
    CHECK(r == eval1("rand(SF)", v));              // across expressions
    if (r != prev) ++distinct_from_prev;
    prev = r;
    sum += r;
  }
  CHECK(distinct_from_prev == 1000);
  CHECK(sum / 1000 == Approx(0.5).margin(0.05));
  CHECK(eval1("rand(1)") != eval1("rand(2)"));
  CHECK(eval1("rand(0)") == eval1("rand(-0)"));
}

TEST_CASE("linear keyframes", "[keyframes]") {
  Keyframes k;
  k.keys = {{0, 0.0}, {1.5, 2.0}, {3, 1.0}};
  CHECK(k.eval(0.75) == Approx(1.0));
  CHECK(k.eval(2.25) == Approx(1.5));
  CHECK(k.eval(1.5) == Approx(2.0));
  // held outside the range
  CHECK(k.eval(-1) == 0.0);
  CHECK(k.eval(10) == 1.0);
  // one key: constant; none: 0
  Keyframes one;
  one.keys = {{1, 7}};
  CHECK(one.eval(0) == 7);
  CHECK(one.eval(5) == 7);
  CHECK(Keyframes{}.eval(1) == 0);
}

TEST_CASE("cubic keyframes pass through the keys and curve between them", "[keyframes]") {
  Keyframes lin, cub;
  lin.keys = cub.keys = {{0, 0.0}, {1, 2.0}, {2, 0.5}, {4, 3.0}};
  cub.cubic = true;
  for (const auto& [t, val] : cub.keys) CHECK(cub.eval(t) == Approx(val));
  // between keys of a non-linear set, cubic differs from linear
  for (double t : {0.5, 1.5, 3.0}) {
    INFO("t = " << t);
    CHECK(std::abs(cub.eval(t) - lin.eval(t)) > 1e-3);
  }
  // continuous across a key
  CHECK(cub.eval(1 - 1e-9) == Approx(2.0).margin(1e-6));
  CHECK(cub.eval(1 + 1e-9) == Approx(2.0).margin(1e-6));
  // held outside the range
  CHECK(cub.eval(-3) == 0.0);
  CHECK(cub.eval(9) == 3.0);
  // two keys: a smooth curve through both
  Keyframes two;
  two.keys = {{0, 1.0}, {2, 5.0}};
  two.cubic = true;
  CHECK(two.eval(0) == Approx(1.0));
  CHECK(two.eval(2) == Approx(5.0));
  CHECK(two.eval(1) == Approx(3.0));
}

TEST_CASE("channels evaluate constants, expressions and keyframes", "[channel]") {
  ExprVars v;
  v.ST = 0.75;
  v.SF = 18;
  Channel c = Channel::constant(2.5);
  CHECK(c.is_constant());
  CHECK(c.eval(v) == 2.5);
  Channel d;
  CHECK(d.is_constant());
  CHECK(d.eval(v) == 0);
  Channel e = Channel::expression("$SF / 2", {});
  CHECK_FALSE(e.is_constant());
  CHECK(e.eval(v) == 9);
  Keyframes k;
  k.keys = {{0, 0.0}, {1.5, 2.0}};
  Channel kc = Channel::keyframes(k);
  CHECK_FALSE(kc.is_constant());
  CHECK(kc.eval(v) == Approx(1.0));
  // moved expressions keep their bound variables
  Expression moved("ST + activation", {"activation"});
  Expression target = std::move(moved);
  std::map<std::string, double> prev = {{"activation", 1}};
  v.channels = &prev;
  CHECK(target.eval(v) == Approx(1.75));
  CHECK(target.text() == "ST + activation");
}

TEST_CASE("an expression says which bound variables it reads", "[expression]") {
  // the attribute node takes the positions and velocities only for an expression that reads
  // them (a grains node may hold them elsewhere: engine/particles.h)
  double tx = 0, vx = 0;
  const std::vector<std::pair<std::string, double*>> bound = {
      {"TX", &tx}, {"$TX", &tx}, {"VX", &vx}, {"$VX", &vx}};
  const Expression reads("$TX * 2 + if($F > 3, VX, 0)", {}, bound);
  CHECK(reads.uses("$TX"));
  CHECK_FALSE(reads.uses("TX"));
  CHECK(reads.uses("VX"));
  CHECK_FALSE(reads.uses("$VX"));
  const Expression none("strcmp($OBJNAME, \"sand\") + $F", {}, bound);
  CHECK_FALSE(none.uses("TX"));
  CHECK_FALSE(none.uses("$TX"));
  CHECK_FALSE(none.uses("VX"));
}
