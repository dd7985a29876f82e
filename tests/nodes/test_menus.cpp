// Menus are read as enums (ParamSet::choice): each enum's order must be its menu's.
#include <catch2/catch.hpp>

#include "engine/collider.h"
#include "tests/support/support.h"

using namespace grains;

TEST_CASE("the collider's shape menu is in ShapeKind's order", "[nodes][colliders]") {
  register_builtin_nodes();
  const NodeTypeInfo* collider = find_node_type("collider");
  REQUIRE(collider);
  const ParamDecl* shape = collider->find_param("shape");
  REQUIRE(shape);
  REQUIRE(shape->menu.size() == 6);
  for (size_t k = 0; k < shape->menu.size(); ++k)
    CHECK(shape->menu[k] == shape_name(static_cast<ShapeKind>(k)));
}

TEST_CASE("a menu's choice is its number in the declaration, the default's when not authored",
          "[nodes]") {
  const std::vector<ParamDecl> decls = {
      ParamDecl::Menu("m", {"a", "b", "c"}, "b", "a menu"),
      ParamDecl::Choice("n", 2, "a table's menu").menu_of({"x", "y", "z"})};
  ParamValue c;
  c.text = "c";
  ParamSet authored(decls, {{"m", c}});
  CHECK(authored.choice("m") == 2);
  CHECK(authored.choice("n") == 2);
  CHECK(authored.s("n") == "z");
  ParamSet defaults(decls, {});
  CHECK(defaults.choice("m") == 1);
  CHECK_THROWS_AS(ParamDecl::Choice("bad", 3, "").menu_of({"x"}), std::logic_error);
}
