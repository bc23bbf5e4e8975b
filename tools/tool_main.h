// The shared frame of every command: run the body, and turn any exception into one line on
// stderr and a non-zero exit code, so scripts see a clear failure and never a crash.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <functional>
#include <string>

#include "util/error.h"

namespace paircast {

// Exit codes: 0 success, 1 error (bad input, I/O), 2 bad command line, 3 internal error.
inline int runTool(const char* name, CLI::App& app, int argc, char** argv,
                   const std::function<int()>& body) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    return body();
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", name, e.what());
    return 1;
  } catch (const std::logic_error& e) {
    std::fprintf(stderr, "%s: internal error: %s\n", name, e.what());
    return 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", name, e.what());
    return 1;
  }
}

}  // namespace paircast
