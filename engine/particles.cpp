#include "engine/particles.h"

#include <cctype>
#include <stdexcept>

namespace grains {

const char* attrib_type_name(AttribType t) {
  switch (t) {
    case AttribType::Float: return "float";
    case AttribType::Int: return "int";
    case AttribType::Vec3: return "vector";
  }
  return "?";
}

const std::vector<AttribDefault>& known_point_attributes() {
  static const std::vector<AttribDefault> table = {
      {"P", AttribType::Vec3, {0, 0, 0}, "position (m)"},
      {"v", AttribType::Vec3, {0, 0, 0}, "velocity (m/s)"},
      {"force", AttribType::Vec3, {0, 0, 0}, "accumulated force (N), cleared every substep"},
      {"mass", AttribType::Float, {1, 0, 0}, "mass (kg)"},
      {"pscale", AttribType::Float, {0.05f, 0, 0}, "radius (m); sources set separation/2"},
      {"id", AttribType::Int, {0, 0, 0}, "unique, stable point id"},
      {"ispbd", AttribType::Int, {0, 0, 0}, "1 when a grains node moved the point this substep"},
      {"streamid", AttribType::Int, {-1, 0, 0}, "index of the source node that emitted the point"},
      {"age", AttribType::Float, {0, 0, 0}, "seconds since birth"},
      {"friction", AttribType::Float, {1, 0, 0}, "scales both grains friction parameters"},
      {"repulsionweight", AttribType::Float, {1, 0, 0}, "scales internal collision weight"},
      {"repulsionstiffness", AttribType::Float, {1, 0, 0}, "scales internal collision stiffness"},
      {"attractionweight", AttribType::Float, {1, 0, 0}, "scales clumping weight"},
      {"attractionstiffness", AttribType::Float, {1, 0, 0}, "scales clumping stiffness"},
      {"constraintweight", AttribType::Float, {1, 0, 0}, "scales explicit constraint weight"},
      {"constraintstiffness", AttribType::Float, {1, 0, 0}, "scales explicit constraint stiffness"},
      {"targetP", AttribType::Vec3, {0, 0, 0}, "pin target position (m)"},
      {"targetweight", AttribType::Float, {1, 0, 0}, "scales pin weight"},
      {"targetstiffness", AttribType::Float, {0, 0, 0}, "scales pin stiffness; missing = no pin"},
      {"shockmass", AttribType::Float, {1, 0, 0}, "virtual mass of global mass-shock scaling"},
      {"rest", AttribType::Vec3, {0, 0, 0}, "rest position (m), written by sources"},
      {"impact", AttribType::Int, {0, 0, 0}, "1 when the grain touched a collider this frame"},
      {"impactimpulse", AttribType::Float, {0, 0, 0}, "summed collider normal impulse this frame (N s)"},
      {"impactP", AttribType::Vec3, {0, 0, 0}, "contact point of the strongest impact (m)"},
      {"impactN", AttribType::Vec3, {0, 0, 0}, "normal of the strongest impact, out of the collider"},
      {"impactother", AttribType::Int, {-1, 0, 0}, "collider index of the strongest impact; -1 none"},
  };
  return table;
}

const AttribDefault* find_known_attribute(std::string_view name) {
  for (const auto& a : known_point_attributes())
    if (name == a.name) return &a;
  return nullptr;
}

std::string group_attribute(std::string_view group) { return "group_" + std::string(group); }

std::string group_name_problem(std::string_view group) {
  bool plain = !group.empty() && !std::isdigit(static_cast<unsigned char>(group[0]));
  for (char c : group) plain = plain && (std::isalnum(static_cast<unsigned char>(c)) || c == '_');
  if (plain) return "";
  return "a group name is letters, digits and '_', not starting with a digit; got '" +
         std::string(group) + "'";
}

ParticleStore::ParticleStore() {
  for (const char* name : {"P", "v", "force", "mass", "pscale", "id", "ispbd"}) add(name);
}

void ParticleStore::resize_attribute(Attribute& a, std::string_view name, size_t n) const {
  const AttribDefault* d = find_known_attribute(name);
  if (a.type == AttribType::Int) {
    a.i.resize(n, d ? static_cast<int32_t>(d->value[0]) : 0);
    return;
  }
  int c = a.components();
  size_t old = a.f.size() / c;
  a.f.resize(n * c);
  for (size_t k = old; k < n; ++k)
    for (int j = 0; j < c; ++j) a.f[k * c + j] = d ? d->value[j] : 0.0f;
}

AttributeHolds& AttributeHolds::operator=(const AttributeHolds& o) {
  o.fetch_all();
  holds_.clear();  // this store's arrays are replaced by the copy's
  return *this;
}
AttributeHolds& AttributeHolds::operator=(AttributeHolds&& o) {
  o.fetch_all();
  holds_.clear();
  return *this;
}

void AttributeHolds::hold(std::string_view name, const void* owner, std::function<void()> fetch) {
  fetch_held(name);  // an earlier holder's values first
  holds_.push_back({std::string(name), owner, std::move(fetch)});
}
bool AttributeHolds::held(std::string_view name) const {
  for (const Hold& h : holds_)
    if (h.name == name) return true;
  return false;
}
bool AttributeHolds::held_by(std::string_view name, const void* owner) const {
  for (const Hold& h : holds_)
    if (h.name == name && h.owner == owner) return true;
  return false;
}
const void* AttributeHolds::holder(std::string_view name) const {
  for (const Hold& h : holds_)
    if (h.name == name) return h.owner;
  return nullptr;
}
void AttributeHolds::claim(std::string_view name, const void* owner) {
  for (size_t k = 0; k < holds_.size(); ++k)
    if (holds_[k].name == name && holds_[k].owner == owner) {
      holds_.erase(holds_.begin() + static_cast<long>(k));
      return;
    }
}
// the hold is dropped before its fetch runs: the fetch writes through the store's accessors
void AttributeHolds::fetch_held(std::string_view name) const {
  for (size_t k = 0; k < holds_.size(); ++k)
    if (holds_[k].name == name) {
      std::function<void()> f = std::move(holds_[k].fetch);
      holds_.erase(holds_.begin() + static_cast<long>(k));
      f();
      return;
    }
}
void AttributeHolds::fetch_all() const {
  while (!holds_.empty()) fetch_held(std::string(holds_.front().name));
}

Attribute& ParticleStore::add(std::string_view name, AttribType type) {
  holds_.fetch(name);
  auto it = attribs_.find(name);
  if (it != attribs_.end()) {
    if (it->second.type != type)
      throw std::runtime_error("attribute '" + std::string(name) + "' is " +
                               attrib_type_name(it->second.type) + ", not " +
                               attrib_type_name(type));
    return it->second;
  }
  Attribute& a = attribs_[std::string(name)];
  a.type = type;
  resize_attribute(a, name, n_);
  return a;
}

Attribute& ParticleStore::add(std::string_view name) {
  const AttribDefault* d = find_known_attribute(name);
  if (!d) throw std::runtime_error("unknown attribute '" + std::string(name) + "' needs a type");
  return add(name, d->type);
}

Attribute* ParticleStore::find(std::string_view name) {
  holds_.fetch(name);
  auto it = attribs_.find(name);
  return it == attribs_.end() ? nullptr : &it->second;
}
const Attribute* ParticleStore::find(std::string_view name) const {
  holds_.fetch(name);
  auto it = attribs_.find(name);
  return it == attribs_.end() ? nullptr : &it->second;
}
void ParticleStore::remove_attribute(std::string_view name) {
  holds_.fetch(name);
  auto it = attribs_.find(name);
  if (it != attribs_.end()) attribs_.erase(it);
}

const float* ParticleStore::f_if(std::string_view name) const {
  const Attribute* a = find(name);
  return a && a->type == AttribType::Float ? a->f.data() : nullptr;
}
const int32_t* ParticleStore::i_if(std::string_view name) const {
  const Attribute* a = find(name);
  return a && a->type == AttribType::Int ? a->i.data() : nullptr;
}
const float* ParticleStore::v3_if(std::string_view name) const {
  const Attribute* a = find(name);
  return a && a->type == AttribType::Vec3 ? a->f.data() : nullptr;
}

size_t ParticleStore::add_points(size_t count) {
  holds_.fetch_all();
  size_t first = n_;
  n_ += count;
  for (auto& [name, a] : attribs_) resize_attribute(a, name, n_);
  int32_t* id = attribs_.at("id").i.data();
  for (size_t k = first; k < n_; ++k) id[k] = next_id_++;
  return first;
}

void ParticleStore::remove_points(const std::vector<uint8_t>& dead) {
  if (dead.size() != n_) throw std::logic_error("remove_points: mask size differs from point count");
  holds_.fetch_all();
  std::vector<int32_t> remap(n_, -1);
  size_t kept = 0;
  for (size_t k = 0; k < n_; ++k)
    if (!dead[k]) remap[k] = static_cast<int32_t>(kept++);
  if (kept == n_) return;
  for (auto& [name, a] : attribs_) {
    int c = a.components();
    for (size_t k = 0; k < n_; ++k) {
      if (remap[k] < 0) continue;
      size_t d = static_cast<size_t>(remap[k]);
      if (a.type == AttribType::Int)
        a.i[d] = a.i[k];
      else
        for (int j = 0; j < c; ++j) a.f[d * c + j] = a.f[k * c + j];
    }
    if (a.type == AttribType::Int)
      a.i.resize(kept);
    else
      a.f.resize(kept * c);
  }
  n_ = kept;
  // primitives: drop those touching a dead point, renumber the rest
  std::vector<uint8_t> dead_prim(prim_count(), 0);
  for (size_t p = 0; p < prim_count(); ++p) {
    int32_t a = remap[prim_points_[2 * p]], b = remap[prim_points_[2 * p + 1]];
    if (a < 0 || b < 0) dead_prim[p] = 1;
    else {
      prim_points_[2 * p] = a;
      prim_points_[2 * p + 1] = b;
    }
  }
  remove_prims(dead_prim);
}

void ParticleStore::set_group(std::string_view group, size_t point, bool member) {
  i(group_attribute(group))[point] = member ? 1 : 0;
}
bool ParticleStore::in_group(std::string_view group, size_t point) const {
  const int32_t* g = i_if(group_attribute(group));
  return g && g[point] != 0;
}

size_t ParticleStore::add_prim(int32_t a, int32_t b) {
  prim_points_.push_back(a);
  prim_points_.push_back(b);
  size_t m = prim_count();
  for (auto& [name, v] : prim_attribs_) v.resize(m, name == "strength" ? 1.0f : 0.0f);
  return m - 1;
}

float* ParticleStore::prim_f(std::string_view name) {
  auto it = prim_attribs_.find(name);
  if (it == prim_attribs_.end())
    it = prim_attribs_.emplace(std::string(name),
                               std::vector<float>(prim_count(), name == "strength" ? 1.0f : 0.0f))
             .first;
  return it->second.data();
}
const float* ParticleStore::prim_f_if(std::string_view name) const {
  auto it = prim_attribs_.find(name);
  return it == prim_attribs_.end() ? nullptr : it->second.data();
}

void ParticleStore::remove_prims(const std::vector<uint8_t>& dead) {
  size_t m = prim_count(), kept = 0;
  for (size_t p = 0; p < m; ++p) {
    if (dead[p]) continue;
    prim_points_[2 * kept] = prim_points_[2 * p];
    prim_points_[2 * kept + 1] = prim_points_[2 * p + 1];
    for (auto& [name, v] : prim_attribs_) v[kept] = v[p];
    ++kept;
  }
  prim_points_.resize(2 * kept);
  for (auto& [name, v] : prim_attribs_) v.resize(kept);
}

}  // namespace grains
