// Number checks for command-line options, with plain messages (CLI11's PositiveNumber prints the
// whole double range, 309 digits). Floating-point options are also checked to be finite and
// within the float range after parsing (cli.cpp, check_float_options).
#pragma once
#include <CLI/CLI.hpp>
#include <cmath>
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
  return CLI::Validator([](std::string& t) { return number_at_least(t, 0, false); },
                        "NONNEGATIVE");
}

}  // namespace grains
