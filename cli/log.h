// The messages of both programs (`grains`, `grains-lab`) on stderr, through one spdlog logger:
// errors ("grains: error: ..."), warnings, progress and, with --verbose, each frame's detail.
// Standard output stays the commands' results (validate, nodes, schema, heap), never logged.
//
// The logger writes each message as it is, one line (spdlog pattern "%v": no time, no level
// name), since users and tests read them: the text of "grains: error: ..." is part of the
// interface. The options choose its level:
//   --quiet    warn:  errors and warnings only (a warning is never silenced)
//   (default)  info:  progress and what was written
//   --verbose  debug: also each phase and each frame's detail
// Code logs with spdlog's free functions (spdlog::info, spdlog::debug, ...) on the default
// logger, which set_log_level makes this one; the engine may log at debug the same way.
#pragma once
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

namespace grains {

// The level the options ask for: warn with --quiet, debug with --verbose, else info.
inline spdlog::level::level_enum log_level(bool quiet, bool verbose) {
  if (quiet) return spdlog::level::warn;
  return verbose ? spdlog::level::debug : spdlog::level::info;
}

// Makes the stderr logger spdlog's default (once; spdlog's own default writes to stdout with a
// time and level prefix) and sets its level. Each command calls it before its first message.
inline void set_log_level(bool quiet, bool verbose) {
  static const std::shared_ptr<spdlog::logger> logger = [] {
    auto l = std::make_shared<spdlog::logger>("grains",
                                              std::make_shared<spdlog::sinks::stderr_sink_mt>());
    l->set_pattern("%v");  // the sink flushes after each line
    spdlog::set_default_logger(l);
    return l;
  }();
  logger->set_level(log_level(quiet, verbose));
}

// Whether --verbose is in effect (each frame's detail is logged).
inline bool log_verbose() {
  return spdlog::should_log(spdlog::level::debug);
}

// Adds --quiet and --verbose (either, not both) to a command.
inline void add_verbosity_flags(CLI::App* cmd, bool& quiet, bool& verbose) {
  auto* q = cmd->add_flag("--quiet", quiet, "print only errors and warnings");
  auto* v = cmd->add_flag("--verbose", verbose, "also print each phase and each frame's detail");
  q->excludes(v);
}

}  // namespace grains
