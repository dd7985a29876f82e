// Expressions (muparser), keyframes and channels; see expression.h and DESIGN §2.
#include "engine/expression.h"

#include <muParser.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string_view>

namespace grains {

namespace {

constexpr const char* kNameChars =
    "0123456789_abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ$@";

bool is_name_char(char c) {
  return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_' ||
         c == '$';
}

bool is_valid_name(const std::string& s) {
  if (s.empty() || (s[0] >= '0' && s[0] <= '9')) return false;
  return std::all_of(s.begin(), s.end(), is_name_char);
}

// ---- functions Houdini users expect (HScript argument order) ----

// fit(value, oldmin, oldmax, newmin, newmax): value clamped to the old range, mapped to the new.
double fn_fit(double x, double omin, double omax, double nmin, double nmax) {
  const double d = omax - omin;
  if (d == 0) return 0.5 * (nmin + nmax);
  if (omin < omax) {
    if (x <= omin) return nmin;
    if (x >= omax) return nmax;
  } else {
    if (x >= omin) return nmin;
    if (x <= omax) return nmax;
  }
  return nmin + (nmax - nmin) * (x - omin) / d;
}
double fn_fit01(double x, double nmin, double nmax) { return fn_fit(x, 0, 1, nmin, nmax); }
double fn_fit10(double x, double nmin, double nmax) { return fn_fit(x, 1, 0, nmin, nmax); }
double fn_fit11(double x, double nmin, double nmax) { return fn_fit(x, -1, 1, nmin, nmax); }
// efit: fit without clamping.
double fn_efit(double x, double omin, double omax, double nmin, double nmax) {
  const double d = omax - omin;
  if (d == 0) return 0.5 * (nmin + nmax);
  return nmin + (nmax - nmin) * (x - omin) / d;
}
double fn_clamp(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }
// smooth(value, min, max): 0 below min, 1 above max, smoothstep ease in between (HScript order).
double fn_smooth(double x, double lo, double hi) {
  if (hi == lo) return x < lo ? 0.0 : 1.0;
  double t = (x - lo) / (hi - lo);
  t = fn_clamp(t, 0, 1);
  return t * t * (3 - 2 * t);
}
double fn_lerp(double a, double b, double t) { return a + (b - a) * t; }
double fn_if(double c, double a, double b) { return c != 0 ? a : b; }
double fn_deg(double radians) { return radians * (180.0 / 3.14159265358979323846); }
double fn_rad(double degrees) { return degrees * (3.14159265358979323846 / 180.0); }
double fn_floor(double x) { return std::floor(x); }
double fn_ceil(double x) { return std::ceil(x); }
double fn_round(double x) { return std::round(x); }
double fn_trunc(double x) { return std::trunc(x); }
double fn_frac(double x) { return x - std::floor(x); }
double fn_pow(double a, double b) { return std::pow(a, b); }
double fn_mod(double a, double b) {
  // Houdini-style modulo: result has the sign of the divisor.
  if (b == 0) return 0;
  double r = std::fmod(a, b);
  if (r != 0 && ((r < 0) != (b < 0))) r += b;
  return r;
}

// rand(seed): deterministic in [0, 1), a hash of the seed's bits (splitmix64 finaliser).
double fn_rand(double seed) {
  if (seed == 0) seed = 0;  // -0 and +0 give the same value
  uint64_t bits = 0;
  std::memcpy(&bits, &seed, sizeof bits);
  uint64_t z = bits + 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) * (1.0 / 9007199254740992.0);  // 53 bits / 2^53
}

std::string format_error(const mu::Parser::exception_type& e, const std::string& text) {
  return "expression \"" + text + "\": " + e.GetMsg();
}

// ---- strcmp resolution: the only string operation; resolved textually before muparser ----

// The string variables strcmp compares, in the order their values are kept.
constexpr std::array<const char*, 9> kStringNames = {
    "OBJNAME",     "DOPNET",    "ALLOBJIDS",   "ALLOBJNAMES",   "RELNAME",
    "RELOBJIDS",   "RELOBJNAMES", "RELAFFOBJIDS", "RELAFFOBJNAMES"};
using StringValues = std::array<std::string, kStringNames.size()>;
StringValues string_values(const ExprVars& v) {
  return {v.OBJNAME, v.DOPNET, v.ALLOBJIDS, v.ALLOBJNAMES, "", "", "", "", ""};  // REL*: ExprVars
}

struct StrOperand {
  int var = -1;  // index into kStringNames, or -1 for the literal
  std::string literal;
};
struct StrcmpCall {
  size_t begin = 0, end = 0;  // [begin, end) in the original text
  StrOperand a, b;
};

// A text split into the strcmp calls it holds; resolve() substitutes their values.
struct StringTemplate {
  std::string text;
  std::vector<StrcmpCall> calls;
  std::array<bool, kStringNames.size()> uses{};  // which string variables the calls read

  static void skip_ws(const std::string& s, size_t& i) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\n' || s[i] == '\r')) ++i;
  }

  // Parses a string literal starting at s[i] == '"'; supports \" and \\ escapes.
  static bool read_literal(const std::string& s, size_t& i, std::string& out) {
    ++i;
    out.clear();
    while (i < s.size()) {
      char c = s[i++];
      if (c == '"') return true;
      if (c == '\\' && i < s.size()) c = s[i++];
      out.push_back(c);
    }
    return false;
  }

  static std::string read_name(const std::string& s, size_t& i) {
    size_t j = i;
    while (j < s.size() && is_name_char(s[j])) ++j;
    std::string n = s.substr(i, j - i);
    i = j;
    return n;
  }

  [[noreturn]] static void fail(const std::string& text, const std::string& why) {
    throw ExprError("expression \"" + text + "\": " + why);
  }

  StrOperand read_operand(size_t& i) {
    const std::string& s = text;
    skip_ws(s, i);
    StrOperand op;
    if (i < s.size() && s[i] == '"') {
      if (!read_literal(s, i, op.literal)) fail(text, "unterminated string literal");
      return op;
    }
    std::string n = read_name(s, i);
    if (!n.empty() && n[0] == '$') n.erase(0, 1);
    for (size_t k = 0; k < kStringNames.size(); ++k)
      if (n == kStringNames[k]) op.var = static_cast<int>(k);
    if (op.var < 0) {
      std::string names;
      for (const char* name : kStringNames) {
        if (!names.empty()) names += ", ";
        names += '$';
        names += name;
      }
      fail(text, "strcmp takes string literals (\"...\") or the string variables " + names);
    }
    uses[op.var] = true;
    return op;
  }

  explicit StringTemplate(const std::string& t) : text(t) {
    const std::string& s = text;
    size_t i = 0;
    while (i < s.size()) {
      const char c = s[i];
      if (c == '"') {  // a stray literal: leave it for muparser to reject
        std::string ignored;
        read_literal(s, i, ignored);
        continue;
      }
      if (!is_name_char(c)) {
        ++i;
        continue;
      }
      const size_t start = i;
      const std::string n = read_name(s, i);
      if (n != "strcmp") continue;
      size_t j = i;
      skip_ws(s, j);
      if (j >= s.size() || s[j] != '(') fail(text, "strcmp must be followed by '('");
      ++j;
      StrcmpCall call;
      call.begin = start;
      call.a = read_operand(j);
      skip_ws(s, j);
      if (j >= s.size() || s[j] != ',') fail(text, "strcmp takes two arguments");
      ++j;
      call.b = read_operand(j);
      skip_ws(s, j);
      if (j >= s.size() || s[j] != ')') fail(text, "strcmp takes two arguments");
      ++j;
      call.end = j;
      calls.push_back(std::move(call));
      i = j;
    }
  }

  std::string resolve(const StringValues& values) const {
    if (calls.empty()) return text;
    auto value = [&](const StrOperand& op) -> const std::string& {
      return op.var < 0 ? op.literal : values[op.var];
    };
    std::string out;
    out.reserve(text.size());
    size_t pos = 0;
    for (const StrcmpCall& c : calls) {
      out.append(text, pos, c.begin - pos);
      const int cmp = value(c.a).compare(value(c.b));
      out += cmp == 0 ? "(0)" : (cmp < 0 ? "(-1)" : "(1)");
      pos = c.end;
    }
    out.append(text, pos, std::string::npos);
    return out;
  }
};

constexpr size_t kNumLocals = 15;
constexpr std::array<const char*, kNumLocals> kLocalNames = {
    "ST",  "SF",    "T",     "F",     "TIMESTEP", "SFPS",   "OBJ",  "OBJID",
    "NOBJ", "SNOBJ", "OBJCT", "OBJCF", "DATACT",   "DATACF", "FF"};

// ch("name"), as Houdini users read a parameter of the same node, becomes the channel `name`
// (the node's own channel, its previous value: a vector's components are NAMEx, NAMEy, NAMEz).
// A name that is no channel of the node is refused with the names it has.
std::string rewrite_ch(const std::string& text, const std::vector<std::string>& channels) {
  using T = StringTemplate;
  std::string out;
  size_t i = 0;
  while (i < text.size()) {
    const char c = text[i];
    if (c == '"') {  // a string literal (strcmp's): copied as it is
      const size_t start = i;
      std::string ignored;
      T::read_literal(text, i, ignored);
      out.append(text, start, i - start);
      continue;
    }
    if (!is_name_char(c)) {
      out += c;
      ++i;
      continue;
    }
    const std::string name = T::read_name(text, i);
    size_t k = i;
    T::skip_ws(text, k);
    if (name != "ch" || k >= text.size() || text[k] != '(') {
      out += name;
      continue;
    }
    // ch ( "name" )
    size_t q = k + 1;
    T::skip_ws(text, q);
    std::string channel;
    bool ok = q < text.size() && text[q] == '"' && T::read_literal(text, q, channel);
    if (ok) T::skip_ws(text, q);
    if (!ok || q >= text.size() || text[q] != ')')
      throw ExprError("expression \"" + text + "\": ch takes one channel name in quotes, ch(\"name\")");
    if (std::find(channels.begin(), channels.end(), channel) == channels.end()) {
      std::string have;
      for (const std::string& n : channels) have += (have.empty() ? "" : ", ") + n;
      throw ExprError("expression \"" + text + "\": ch(\"" + channel + "\"): the node has no channel '" +
                      channel + "'" + (have.empty() ? std::string() : " (its channels: " + have + ")"));
    }
    out += "(" + channel + ")";
    i = q + 1;
  }
  return out;
}

}  // namespace

struct Expression::Impl {
  std::string text;
  StringTemplate tmpl;
  mu::Parser parser;
  std::array<double, kNumLocals> locals{};
  std::vector<std::string> channel_names;  // bound channels, same order as channel_values
  std::unique_ptr<double[]> channel_values;
  StringValues last;  // the string variables the parser was last compiled with

  Impl(const std::string& t, const std::vector<std::string>& names,
       const std::vector<std::pair<std::string, double*>>& bound)
      : text(t), tmpl(rewrite_ch(t, names)) {
    try {
      parser.DefineNameChars(kNameChars);
      for (const auto& [n, value] : bound) parser.DefineVar(n, value);
      for (size_t k = 0; k < kNumLocals; ++k) {
        const std::string n = kLocalNames[k];
        parser.DefineVar(n, &locals[k]);
        parser.DefineVar("$" + n, &locals[k]);
      }
      // channels: skip invalid names and names that shadow a local variable (locals win)
      for (const std::string& n : names) {
        if (!is_valid_name(n) || n[0] == '$') continue;
        if (std::find(kLocalNames.begin(), kLocalNames.end(), std::string_view(n)) !=
            kLocalNames.end())
          continue;
        if (std::find(channel_names.begin(), channel_names.end(), n) != channel_names.end()) continue;
        channel_names.push_back(n);
      }
      channel_values = std::make_unique<double[]>(channel_names.size());
      for (size_t k = 0; k < channel_names.size(); ++k) {
        channel_values[k] = 0;
        parser.DefineVar(channel_names[k], &channel_values[k]);
        parser.DefineVar("$" + channel_names[k], &channel_values[k]);
      }
      parser.DefineFun("fit", fn_fit);
      parser.DefineFun("efit", fn_efit);
      parser.DefineFun("fit01", fn_fit01);
      parser.DefineFun("fit10", fn_fit10);
      parser.DefineFun("fit11", fn_fit11);
      parser.DefineFun("clamp", fn_clamp);
      parser.DefineFun("smooth", fn_smooth);
      parser.DefineFun("lerp", fn_lerp);
      parser.DefineFun("if", fn_if);
      parser.DefineFun("deg", fn_deg);
      parser.DefineFun("rad", fn_rad);
      parser.DefineFun("floor", fn_floor);
      parser.DefineFun("ceil", fn_ceil);
      parser.DefineFun("round", fn_round);
      parser.DefineFun("trunc", fn_trunc);
      parser.DefineFun("frac", fn_frac);
      parser.DefineFun("pow", fn_pow);
      parser.DefineFun("mod", fn_mod);
      parser.DefineFun("rand", fn_rand);
      // validate now, with empty strings, so parse errors surface at load time
      parser.SetExpr(tmpl.resolve(last));
      parser.Eval();
    } catch (const mu::Parser::exception_type& e) {
      throw ExprError(format_error(e, text));
    }
  }

  double eval(const ExprVars& v) {
    locals = {v.ST,   v.SF,    v.T,     v.F,     v.TIMESTEP, v.SFPS,   v.OBJ, v.OBJID,
              v.NOBJ, v.SNOBJ, v.OBJCT, v.OBJCF, v.DATACT,   v.DATACF, v.F};  // FF: F, fractional
    for (size_t k = 0; k < channel_names.size(); ++k) {
      double x = 0;
      if (v.channels) {
        auto it = v.channels->find(channel_names[k]);
        if (it != v.channels->end()) x = it->second;
      }
      channel_values[k] = x;
    }
    try {
      bool changed = false;
      if (!tmpl.calls.empty()) {
        StringValues now = string_values(v);
        for (size_t k = 0; k < now.size(); ++k) changed = changed || (tmpl.uses[k] && now[k] != last[k]);
        if (changed) {
          const std::string before = tmpl.resolve(last);
          last = std::move(now);
          std::string after = tmpl.resolve(last);
          if (after != before) parser.SetExpr(after);
        }
      }
      return parser.Eval();
    } catch (const mu::Parser::exception_type& e) {
      throw ExprError(format_error(e, text));
    }
  }
};

Expression::Expression(const std::string& text, const std::vector<std::string>& channel_names,
                       const std::vector<std::pair<std::string, double*>>& bound)
    : impl_(std::make_unique<Impl>(text, channel_names, bound)) {}
Expression::~Expression() = default;
Expression::Expression(Expression&&) noexcept = default;
Expression& Expression::operator=(Expression&&) noexcept = default;

double Expression::eval(const ExprVars& vars) { return impl_->eval(vars); }

const std::string& Expression::text() const { return impl_->text; }

bool Expression::uses(const std::string& name) const {
  try {
    return impl_->parser.GetUsedVar().count(name) != 0;
  } catch (const mu::Parser::exception_type&) {
    return true;  // parsed at construction: not reached; a read assumed
  }
}

// ---- keyframes ----

double Keyframes::eval(double t) const {
  const size_t n = keys.size();
  if (n == 0) return 0;
  if (t <= keys.front().first || n == 1) return keys.front().second;
  if (t >= keys.back().first) return keys.back().second;
  // segment i: keys[i].first <= t < keys[i+1].first
  auto it = std::upper_bound(keys.begin(), keys.end(), t,
                             [](double x, const std::pair<double, double>& k) { return x < k.first; });
  const size_t i = static_cast<size_t>(it - keys.begin()) - 1;
  const double t0 = keys[i].first, t1 = keys[i + 1].first;
  const double p0 = keys[i].second, p1 = keys[i + 1].second;
  const double h = t1 - t0;
  if (!(h > 0)) return p1;
  const double s = (t - t0) / h;
  if (!cubic) return p0 + (p1 - p0) * s;
  // Catmull-Rom (non-uniform, finite-difference tangents); one-sided differences at the ends.
  auto tangent = [&](size_t k) {
    const size_t a = k == 0 ? 0 : k - 1;
    const size_t b = k + 1 >= n ? n - 1 : k + 1;
    const double dt = keys[b].first - keys[a].first;
    return dt > 0 ? (keys[b].second - keys[a].second) / dt : 0.0;
  };
  const double m0 = tangent(i) * h, m1 = tangent(i + 1) * h;
  const double s2 = s * s, s3 = s2 * s;
  return (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 +
         (s3 - s2) * m1;
}

// ---- channels ----

Channel Channel::constant(double v) {
  Channel c;
  c.kind_ = Kind::Constant;
  c.value_ = v;
  return c;
}

Channel Channel::expression(const std::string& text, const std::vector<std::string>& channel_names) {
  Channel c;
  c.kind_ = Kind::Expr;
  c.expr_ = std::make_shared<Expression>(text, channel_names);
  return c;
}

Channel Channel::keyframes(Keyframes k) {
  Channel c;
  c.kind_ = Kind::Keys;
  c.keys_ = std::move(k);
  return c;
}

double Channel::eval(const ExprVars& vars) {
  switch (kind_) {
    case Kind::Expr: return expr_->eval(vars);
    case Kind::Keys: return keys_.eval(vars.ST);
    case Kind::Constant:
    default: return value_;
  }
}

}  // namespace grains
