// Particle store: a structure of arrays of named, typed point attributes, point groups and
// 2-point polyline primitives (explicit constraints) with primitive attributes.
//
// Every attribute is one contiguous array. Float: (n) values; Vec3: (n x 3) floats; Int: (n).
// Groups are Int attributes named "group_NAME" holding 0 or 1.
// `id` is unique and stable: births take fresh ids from a counter that never goes back,
// deletions compact every array in order, so survivors keep their relative order and ids.
#pragma once
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "engine/vec3.h"

namespace grains {

enum class AttribType { Float, Int, Vec3 };
const char* attrib_type_name(AttribType t);

struct Attribute {
  AttribType type = AttribType::Float;
  std::vector<float> f;    // Float (n) or Vec3 (n x 3)
  std::vector<int32_t> i;  // Int (n)
  int components() const { return type == AttribType::Vec3 ? 3 : 1; }
};

// Documented default of a known attribute; unknown attributes default to zero.
struct AttribDefault {
  const char* name;
  AttribType type;
  float value[3];
  const char* doc;
};
// The table of known point attributes with their defaults (see particles.cpp).
const std::vector<AttribDefault>& known_point_attributes();
const AttribDefault* find_known_attribute(std::string_view name);

std::string group_attribute(std::string_view group);  // "group_" + group
// What is wrong with a group name (it becomes an attribute written to every frame: letters,
// digits and '_', not starting with a digit), or "".
std::string group_name_problem(std::string_view group);

// Held attributes. A node that leaves an attribute's newest values where it made them (an
// OpenCL device, between the substeps of a frame) holds it: `fetch` writes them into the
// store's array, and runs, once, before anything reads or changes that attribute through the
// store: its accessors, `attributes()`, births, deletions, a copy or a move. The holder vouches
// that the values it holds are finite (the engine's check after each node skips them). The
// holder may take its hold back without the fetch (`claim`), going on from the values it kept.
class AttributeHolds {
 public:
  AttributeHolds() = default;
  // a copy or a move: the source's holds fetched first (they write the arrays copied next)
  AttributeHolds(const AttributeHolds& o) { o.fetch_all(); }
  AttributeHolds(AttributeHolds&& o) { o.fetch_all(); }  // a fetch may throw: not noexcept
  AttributeHolds& operator=(const AttributeHolds& o);
  AttributeHolds& operator=(AttributeHolds&& o);

  void hold(std::string_view name, const void* owner, std::function<void()> fetch);
  bool held(std::string_view name) const;
  bool held_by(std::string_view name, const void* owner) const;
  const void* holder(std::string_view name) const;       // null: not held
  void claim(std::string_view name, const void* owner);  // no fetch
  void fetch(std::string_view name) const {
    if (!holds_.empty()) fetch_held(name);
  }
  void fetch_all() const;

 private:
  struct Hold {
    std::string name;
    const void* owner;
    std::function<void()> fetch;
  };
  void fetch_held(std::string_view name) const;
  mutable std::vector<Hold> holds_;
};

class ParticleStore {
 public:
  ParticleStore();  // creates P, v, force, mass, pscale, id, ispbd

  size_t size() const { return n_; }

  // Attributes. `add` creates the attribute with its documented default (or zero) for every
  // existing point, or returns the existing one if its type matches (throws if it does not).
  bool has(std::string_view name) const { return attribs_.count(std::string(name)) != 0; }
  Attribute& add(std::string_view name, AttribType type);
  Attribute& add(std::string_view name);  // type from the known table; throws if unknown
  Attribute* find(std::string_view name);
  const Attribute* find(std::string_view name) const;
  void remove_attribute(std::string_view name);
  const std::map<std::string, Attribute, std::less<>>& attributes() const {
    holds_.fetch_all();
    return attribs_;
  }

  // Raw arrays, created with their defaults if missing.
  float* f(std::string_view name) { return add(name, AttribType::Float).f.data(); }
  int32_t* i(std::string_view name) { return add(name, AttribType::Int).i.data(); }
  float* v3(std::string_view name) { return add(name, AttribType::Vec3).f.data(); }
  // Raw arrays of attributes that must exist (nullptr if missing).
  const float* f_if(std::string_view name) const;
  const int32_t* i_if(std::string_view name) const;
  const float* v3_if(std::string_view name) const;

  // Held attributes (AttributeHolds above).
  void hold(std::string_view name, const void* owner, std::function<void()> fetch) {
    holds_.hold(name, owner, std::move(fetch));
  }
  bool held(std::string_view name) const { return holds_.held(name); }
  const void* holder(std::string_view name) const { return holds_.holder(name); }
  bool held_by(std::string_view name, const void* owner) const {
    return holds_.held_by(name, owner);
  }
  void claim(std::string_view name, const void* owner) { holds_.claim(name, owner); }
  void fetch_held() const { holds_.fetch_all(); }

  // Births: appends `count` points with default attributes and fresh ids; returns the first index.
  size_t add_points(size_t count);
  // Deletions: removes points whose flag is nonzero; primitives touching them are removed too.
  void remove_points(const std::vector<uint8_t>& dead);
  int32_t next_id() const { return next_id_; }
  void set_next_id(int32_t id) { next_id_ = id; }

  // Groups.
  void set_group(std::string_view group, size_t point, bool member);
  bool in_group(std::string_view group, size_t point) const;
  bool has_group(std::string_view group) const { return has(group_attribute(group)); }

  // Primitives: 2-point polylines, (m x 2) point indices, with float primitive attributes.
  size_t prim_count() const { return prim_points_.size() / 2; }
  size_t add_prim(int32_t a, int32_t b);  // returns the primitive index; attributes default 0
  const std::vector<int32_t>& prim_points() const { return prim_points_; }
  std::vector<int32_t>& prim_points() { return prim_points_; }
  float* prim_f(std::string_view name);  // created with 0 (strength: 1) if missing
  const float* prim_f_if(std::string_view name) const;
  const std::map<std::string, std::vector<float>, std::less<>>& prim_attributes() const {
    return prim_attribs_;
  }
  void remove_prims(const std::vector<uint8_t>& dead);

 private:
  void resize_attribute(Attribute& a, std::string_view name, size_t n) const;

  AttributeHolds holds_;  // first: a copy or a move fetches them before the arrays go
  size_t n_ = 0;
  int32_t next_id_ = 0;
  std::map<std::string, Attribute, std::less<>> attribs_;
  std::vector<int32_t> prim_points_;                                   // (m x 2)
  std::map<std::string, std::vector<float>, std::less<>> prim_attribs_;  // each (m)
};

}  // namespace grains
