// One parameter table per node type, as an X-macro list (the grains node's, which also feeds
// its kernels, is nodes/grains/kernels/param_table.h, after MuJoCo's mjxmacro.h). A node lists each parameter
// once:
//   #define FORCE_PARAMS(ROW)
//     ROW(FLOAT, drag, 0, .at_least(0).unit("kg/s"), "drag coefficient") ...
//   GR_NODE_PARAMS(ForceParams, FORCE_PARAMS)
// and the list gives the ParamDecls the loader validates against and `grains nodes`, the docs
// and the schema print (ForceParams::decls()), a struct with one member per row, named as the
// graph names it and holding the row's default, and the read of evaluated parameters into it
// (ForceParams::read(params)). No name or default is written a second time.
//
// ROW(kind, name, default, modifiers, meaning)
//   kind      FLOAT (a double member), INT, TOGGLE, VECTOR, MENU (a Choice), STRING, LIST (names;
//             its default is {})
//   default   a number; VECTOR: (x, y, z); MENU: the default choice's index, with the choices in
//             modifiers as .menu_of({...}); STRING: a literal
//   modifiers ParamDecl modifiers (.at_least(0), .range(0, 1), .unit("m"), ...) or nothing
//   meaning   one line for `grains nodes`
#pragma once
#include <string>
#include <vector>

#include "engine/params.h"

namespace grains {

// A menu's choice: its number in the menu (compare it with the node's enum) and its text.
struct Choice {
  int index = 0;
  std::string text;
  operator int() const { return index; }
};

}  // namespace grains

#define GR_ROW_UNPAREN(...) __VA_ARGS__

#define GR_ROW_TYPE_FLOAT double
#define GR_ROW_TYPE_INT int
#define GR_ROW_TYPE_TOGGLE bool
#define GR_ROW_TYPE_VECTOR ::grains::Vec3
#define GR_ROW_TYPE_MENU ::grains::Choice
#define GR_ROW_TYPE_STRING std::string
#define GR_ROW_TYPE_LIST std::vector<std::string>
#define GR_ROW_INIT_FLOAT(def) def
#define GR_ROW_INIT_INT(def) def
#define GR_ROW_INIT_TOGGLE(def) def
#define GR_ROW_INIT_VECTOR(def) GR_ROW_UNPAREN def
#define GR_ROW_INIT_MENU(def) def, ""
#define GR_ROW_INIT_STRING(def) def
#define GR_ROW_INIT_LIST(def)
#define GR_ROW_MEMBER(kind, name, def, modifiers, meaning) \
  GR_ROW_TYPE_##kind name{GR_ROW_INIT_##kind(def)};

#define GR_ROW_DECL_FLOAT(name, def, meaning) ::grains::ParamDecl::Float(name, def, meaning)
#define GR_ROW_DECL_INT(name, def, meaning) ::grains::ParamDecl::Int(name, def, meaning)
#define GR_ROW_DECL_TOGGLE(name, def, meaning) ::grains::ParamDecl::Toggle(name, def, meaning)
#define GR_ROW_DECL_VECTOR(name, def, meaning) \
  ::grains::ParamDecl::Vector(name, ::grains::Vec3{GR_ROW_UNPAREN def}, meaning)
#define GR_ROW_DECL_MENU(name, def, meaning) ::grains::ParamDecl::Choice(name, def, meaning)
#define GR_ROW_DECL_STRING(name, def, meaning) ::grains::ParamDecl::String(name, def, meaning)
#define GR_ROW_DECL_LIST(name, def, meaning) ::grains::ParamDecl::List(name, meaning)
#define GR_ROW_DECL(kind, name, def, modifiers, meaning) \
  GR_ROW_DECL_##kind(#name, def, meaning) modifiers,

#define GR_ROW_READ_FLOAT(name) p.f(name)
#define GR_ROW_READ_INT(name) p.i(name)
#define GR_ROW_READ_TOGGLE(name) p.b(name)
#define GR_ROW_READ_VECTOR(name) p.v3(name)
#define GR_ROW_READ_MENU(name) ::grains::Choice{p.choice(name), p.s(name)}
#define GR_ROW_READ_STRING(name) p.s(name)
#define GR_ROW_READ_LIST(name) p.list(name)
#define GR_ROW_READ(kind, name, def, modifiers, meaning) out.name = GR_ROW_READ_##kind(#name);

// struct NAME: the rows of ROWS as members, decls() and read(params)
#define GR_NODE_PARAMS(NAME, ROWS)                                          \
  struct NAME {                                                             \
    ROWS(GR_ROW_MEMBER)                                                     \
    static std::vector<::grains::ParamDecl> decls() { return {ROWS(GR_ROW_DECL)}; } \
    static NAME read(const ::grains::ParamSet& p) {                         \
      NAME out;                                                             \
      ROWS(GR_ROW_READ)                                                     \
      return out;                                                           \
    }                                                                       \
  };
