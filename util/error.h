// Two error channels, as in pbrt: CHECK for invariants of our own code (a bug if it fires),
// and paircast::Error for bad user input, which carries the file it concerns.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace paircast {

// A user-facing error: what() is one line that names the offending file when there is one.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
  Error(const std::string& path, const std::string& message)
      : std::runtime_error(path + ": " + message), path_(path) {}
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// A bad option of a library's config struct: `field` names it as the struct and Python do
// (snake_case, e.g. "pairs_per_scene"), and what() says what is wrong in domain terms. A command
// adds its flag's name (tools/tool_main.h), the Python binding its keyword's.
class OptionError : public Error {
 public:
  OptionError(std::string field, const std::string& message)
      : Error(message), field_(std::move(field)) {}
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

[[noreturn]] void checkFailed(const char* file, int line, const char* expr, const std::string& msg);

}  // namespace paircast

#define PAIRCAST_CHECK(cond)                                             \
  do {                                                                   \
    if (!(cond)) ::paircast::checkFailed(__FILE__, __LINE__, #cond, ""); \
  } while (0)

#define PAIRCAST_CHECK_MSG(cond, msg)                                               \
  do {                                                                              \
    if (!(cond)) {                                                                  \
      std::ostringstream paircast_check_os_;                                        \
      paircast_check_os_ << msg;                                                    \
      ::paircast::checkFailed(__FILE__, __LINE__, #cond, paircast_check_os_.str()); \
    }                                                                               \
  } while (0)
