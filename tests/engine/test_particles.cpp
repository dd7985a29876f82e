#include <catch2/catch.hpp>
#include <functional>
#include <vector>

#include "engine/particles.h"

using namespace grains;

TEST_CASE("births give unique ids and documented defaults", "[particles]") {
  ParticleStore s;
  REQUIRE(s.size() == 0);
  size_t first = s.add_points(3);
  REQUIRE(first == 0);
  REQUIRE(s.size() == 3);
  const int32_t* id = s.i_if("id");
  CHECK(id[0] == 0);
  CHECK(id[1] == 1);
  CHECK(id[2] == 2);
  CHECK(s.f_if("mass")[2] == 1.0f);
  // an attribute a node asks for is created with its documented default
  float* friction = s.f("friction");
  CHECK(friction[1] == 1.0f);
  float* ts = s.f("targetstiffness");
  CHECK(ts[0] == 0.0f);
  s.add_points(2);
  CHECK(s.f_if("friction")[4] == 1.0f);
  CHECK(s.i_if("id")[4] == 4);
}

TEST_CASE("deletions compact in order and keep ids stable", "[particles]") {
  ParticleStore s;
  s.add_points(5);
  float* P = s.v3("P");
  for (int k = 0; k < 5; ++k) store3(P, k, Vec3(float(k), 0, 0));
  s.add_prim(0, 1);
  s.add_prim(1, 2);
  s.add_prim(3, 4);
  s.prim_f("restlength")[2] = 7.0f;
  s.remove_points({0, 0, 1, 0, 0});
  REQUIRE(s.size() == 4);
  const int32_t* id = s.i_if("id");
  CHECK(id[0] == 0);
  CHECK(id[2] == 3);
  CHECK(load3(s.v3_if("P"), 2).x == 3.0f);
  // the primitive touching point 2 is gone; the others are renumbered
  REQUIRE(s.prim_count() == 2);
  CHECK(s.prim_points()[2] == 2);
  CHECK(s.prim_points()[3] == 3);
  CHECK(s.prim_f_if("restlength")[1] == 7.0f);
  // new births never reuse an id
  s.add_points(1);
  CHECK(s.i_if("id")[4] == 5);
}

TEST_CASE("groups and type checks", "[particles]") {
  ParticleStore s;
  s.add_points(2);
  s.set_group("top", 1, true);
  CHECK(s.in_group("top", 1));
  CHECK_FALSE(s.in_group("top", 0));
  CHECK_FALSE(s.in_group("missing", 0));
  CHECK_THROWS(s.add("pscale", AttribType::Int));
}

TEST_CASE("a held attribute is fetched once, before the first read or change of it",
          "[particles]") {
  // A node leaves P held (its newest values elsewhere): the fetch writes them, once, at the
  // first access to P through any accessor, and not before; the other attributes are read and
  // written meanwhile without it. A claim takes the hold back without the fetch; births,
  // deletions, attributes() and a copy or a move fetch every hold first.
  ParticleStore s;
  s.add_points(4);
  const int owner = 0;
  int fetches = 0;
  auto hold = [&] {
    s.hold("P", &owner, [&] {
      ++fetches;
      s.v3("P")[3] = 7.0f;  // through the store: the hold is gone by then
    });
  };
  hold();
  CHECK(s.held("P"));
  CHECK(s.held_by("P", &owner));
  CHECK_FALSE(s.held_by("P", &fetches));
  CHECK_FALSE(s.held("v"));
  s.v3("v")[0] = 1.0f;
  s.f("mass")[0] = 2.0f;
  CHECK(s.has("P"));
  CHECK(fetches == 0);
  CHECK(s.v3_if("P")[3] == 7.0f);
  CHECK(fetches == 1);
  CHECK_FALSE(s.held("P"));
  CHECK(s.v3("P")[3] == 7.0f);
  CHECK(fetches == 1);

  hold();
  s.claim("P", &owner);
  CHECK_FALSE(s.held("P"));
  s.v3("P")[3] = 0.0f;
  CHECK(fetches == 1);

  const std::vector<std::function<void()>> fetch_all = {
      [&] { s.add_points(1); },
      [&] { s.remove_points(std::vector<uint8_t>(s.size(), 0)); },
      [&] { CHECK(s.attributes().count("P") == 1); },
      [&] { s.fetch_held(); },
      [&] {
        ParticleStore copy = s;
        CHECK(copy.v3_if("P")[3] == 7.0f);
        CHECK_FALSE(copy.held("P"));
      },
      [&] {
        ParticleStore moved = std::move(s);
        CHECK(moved.v3_if("P")[3] == 7.0f);
        s = moved;
      },
  };
  for (size_t k = 0; k < fetch_all.size(); ++k) {
    INFO("case " << k);
    s.v3("P")[3] = 0.0f;
    hold();
    const int before = fetches;
    fetch_all[k]();
    CHECK(fetches == before + 1);
    CHECK_FALSE(s.held("P"));
    CHECK(s.v3_if("P")[3] == 7.0f);
  }
}
