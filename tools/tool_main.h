// The shared frame of every command: run the body, and turn any exception into one line on
// stderr and a non-zero exit code, so scripts see a clear failure and never a crash.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <functional>
#include <new>
#include <string>

#include "util/blas_core.h"
#include "util/error.h"
#include "util/launch_env.h"

namespace paircast {

// The flag of a library's option field ("pairs_per_scene" -> "--pairs-per-scene"), or "" when
// this command has none by that name.
inline std::string flagOf(const CLI::App& app, const std::string& field) {
  std::string flag = "--" + field;
  for (char& c : flag)
    if (c == '_') c = '-';
  return app.get_option_no_throw(flag) ? flag : "";
}

// The line that says where this process's place in the job came from (LaunchRole::describe,
// JobPart::describe), first on stderr; nothing when there is nothing to say.
inline void logLaunch(const char* name, const std::string& line) {
  if (!line.empty()) std::fprintf(stderr, "%s: %s\n", name, line.c_str());
}

// Before all else, the OpenBLAS core check (util/blas_core.h).
// Exit codes: 0 success, 1 error (bad input, I/O), 2 bad command line, 3 internal error.
// A library's OptionError is a bad command line: the message gets the flag's name.
inline int runTool(const char* name, CLI::App& app, int argc, char** argv,
                   const std::function<int()>& body) {
  checkBlasCore(name, argv);  // may run the command again, with OpenBLAS's right kernels
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every malformed command line exits 2, whatever CLI11 calls it.
    return app.exit(e) == 0 ? 0 : 2;
  }
  try {
    return body();
  } catch (const OptionError& e) {
    const std::string flag = flagOf(app, e.field());
    std::fprintf(stderr, "%s: error: %s%s\n", name, flag.empty() ? "" : (flag + ": ").c_str(),
                 e.what());
    return 2;
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", name, e.what());
    return 1;
  } catch (const std::logic_error& e) {
    std::fprintf(stderr, "%s: internal error: %s\n", name, e.what());
    return 3;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: error: out of memory\n", name);
    return 1;
  } catch (const std::exception& e) {
    // One line: LibTorch's errors carry a backtrace after their message.
    const std::string what = e.what();
    std::fprintf(stderr, "%s: error: %s\n", name, what.substr(0, what.find('\n')).c_str());
    return 1;
  }
}

}  // namespace paircast
