// A progress line on stderr for long work. On a terminal it is one line redrawn in place
// ('\r', then erase to the end of the line); in a log (a file or a pipe), one line every few
// seconds, so that a long run leaves a short log. The last line is always printed.
#pragma once

#include <cstdio>
#include <string>

#include "util/timer.h"

namespace paircast {

class ProgressLine {
 public:
  static constexpr double kTerminalInterval = 0.25;  // seconds between redraws on a terminal
  static constexpr double kLogInterval = 5.0;        // seconds between lines in a log

  // To stderr; in place when stderr is a terminal.
  explicit ProgressLine(bool enabled = true, double logInterval = kLogInterval);
  // To `out`, in place when `inPlace` (tests).
  ProgressLine(std::FILE* out, bool inPlace, double logInterval = kLogInterval);
  ~ProgressLine();  // ends an open in-place line
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  // Whether show() would print now: enabled, and the interval has passed since the last line
  // (the first call always is).
  bool due() const;
  // Prints `text` when due, or always when `last` (which also ends an in-place line).
  void show(const std::string& text, bool last = false);
  // Ends an open in-place line, so that a warning printed next starts on its own line.
  void breakLine();

 private:
  std::FILE* out_;
  bool enabled_, inPlace_, open_ = false, shown_ = false;
  double interval_;
  SteadyClock::time_point last_{};
};

}  // namespace paircast
