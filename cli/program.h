// What the grains and grains-lab programs share around their subcommands: the exit codes, the
// parse of the command line, and the mapping of an error to its exit code and message.
#pragma once
#include <CLI/CLI.hpp>
#include <exception>
#include <iostream>
#include <sstream>
#include <string>

#include "cli/log.h"
#include "cli/options.h"
#include "engine/geometry_io.h"
#include "engine/graph.h"
#include "engine/node.h"

namespace grains {

constexpr int kBadInput = 2;    // the graph, a parameter, a file or an option is wrong
constexpr int kRunFailure = 1;  // a failure while running (a non-finite state, a failed write)

// Parses the command line of `program` and checks its floating-point options. Returns -1 when a
// subcommand is to run, else the exit code: 0 after --help, kBadInput for a bad command line. Sets
// up the logger (cli/log.h) at its default level; the command sets the level its options ask for.
inline int parse_command_line(const char* program, CLI::App& app, int argc, char** argv) {
  set_log_level(false, false);
  // a first word that names no subcommand: say so and list them (CLI11 would say only that a
  // subcommand is required)
  if (argc > 1 && argv[1][0] != '-') {
    std::string names;
    bool known = false;
    for (const CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) {
      known = known || sub->check_name(argv[1]);
      names += (names.empty() ? "" : ", ") + sub->get_name();
    }
    if (!known) {
      spdlog::error("{}: unknown command '{}' (commands: {}; --help for more)", program, argv[1],
                    names);
      return kBadInput;
    }
  }
  try {
    app.parse(argc, argv);
    check_float_options(app);
  } catch (const CLI::ParseError& e) {
    // --help goes to stdout; CLI11's message for a bad command line is logged as an error, the
    // same lines
    std::ostringstream err;
    const int rc = app.exit(e, std::cout, err);
    std::string text = err.str();
    while (!text.empty() && text.back() == '\n') text.pop_back();
    if (!text.empty()) spdlog::error("{}", text);
    return rc == 0 ? 0 : kBadInput;
  }
  return -1;
}

// Runs a subcommand; an error it throws becomes its exit code, with "PROGRAM: error: ..." for
// bad input and "PROGRAM: failed: ..." for a failure while running.
template <class Body>
int report_errors(const char* program, Body&& body) {
  try {
    return body();
  } catch (const LoadError& e) {
    spdlog::error("{}: error: {}", program, e.what());
  } catch (const GeometryError& e) {
    spdlog::error("{}: error: {}", program, e.what());
  } catch (const BudgetError& e) {
    spdlog::error("{}: error: {}", program, e.what());
  } catch (const std::exception& e) {  // a non-finite state, a WriteError (disk full), ...
    spdlog::error("{}: failed: {}", program, e.what());
    return kRunFailure;
  }
  return kBadInput;
}

}  // namespace grains
