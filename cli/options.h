// Number checks for command-line options, with plain messages (CLI11's PositiveNumber prints the
// whole double range, 309 digits), shared by the two programs: `grains` (app/) and `grains-lab`
// (lab/). Floating-point options are also checked to be finite and within the float range after
// parsing (check_float_options).
#pragma once
#include <CLI/CLI.hpp>
#include <cmath>
#include <limits>
#include <string>

namespace grains {

// The option's text as a finite number into v: what is wrong, or "".
inline std::string finite_number_problem(const std::string& text, double& v) {
  try {
    size_t used = 0;
    v = std::stod(text, &used);
    if (used != text.size()) return "'" + text + "' is not a number";
  } catch (const std::exception&) {
    return "'" + text + "' is not a number";
  }
  return std::isfinite(v) ? "" : "'" + text + "' is not a finite number";
}

// The option's text as a number at least (or above) `least`: what is wrong, or "".
inline std::string number_at_least(const std::string& text, double least, bool strictly) {
  double v = 0;
  if (std::string bad = finite_number_problem(text, v); !bad.empty()) return bad;
  if (strictly ? v > least : v >= least) return "";
  return "'" + text + "' must be " + (strictly ? "greater than " : "at least ") +
         (least == 0 ? "0" : std::to_string(least));
}

inline CLI::Validator positive_number() {
  return CLI::Validator([](std::string& t) { return number_at_least(t, 0, true); }, "POSITIVE");
}

inline CLI::Validator non_negative_number() {
  return CLI::Validator([](std::string& t) { return number_at_least(t, 0, false); }, "NONNEGATIVE");
}

// What is wrong with a floating-point option's text, or "": CLI11 reads "nan" and "inf" as
// numbers, and the engine computes in float.
inline std::string float_option_problem(const std::string& text) {
  double v = 0;
  if (std::string bad = finite_number_problem(text, v); !bad.empty()) return bad;
  if (std::fabs(v) > std::numeric_limits<float>::max())
    return "'" + text + "' is beyond the float range";
  return "";
}

// Every floating-point option of the parsed (sub)commands passes float_option_problem.
inline void check_float_options(const CLI::App& app) {
  for (const CLI::Option* o : app.get_options())
    if (o->count() > 0 && o->get_type_name().starts_with("FLOAT"))
      for (const std::string& text : o->results())
        if (std::string bad = float_option_problem(text); !bad.empty())
          throw CLI::ValidationError(o->get_name(), bad);
  for (const CLI::App* sub : app.get_subcommands()) check_float_options(*sub);
}

}  // namespace grains
