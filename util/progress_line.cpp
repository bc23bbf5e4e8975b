#include "util/progress_line.h"

#include <unistd.h>

namespace paircast {

ProgressLine::ProgressLine(bool enabled, double logInterval)
    : ProgressLine(stderr, isatty(fileno(stderr)) == 1, logInterval) {
  enabled_ = enabled;
}

ProgressLine::ProgressLine(std::FILE* out, bool inPlace, double logInterval)
    : out_(out),
      enabled_(true),
      inPlace_(inPlace),
      interval_(inPlace ? kTerminalInterval : logInterval) {}

ProgressLine::~ProgressLine() {
  breakLine();
}

bool ProgressLine::due() const {
  return enabled_ && (!shown_ || secondsSince(last_) >= interval_);
}

void ProgressLine::show(const std::string& text, bool last) {
  if (!enabled_ || !(last || due())) return;
  shown_ = true;
  last_ = SteadyClock::now();
  if (inPlace_) {
    std::fprintf(out_, "\r%s\033[K%s", text.c_str(), last ? "\n" : "");
    open_ = !last;
  } else {
    std::fprintf(out_, "%s\n", text.c_str());
  }
  std::fflush(out_);
}

void ProgressLine::breakLine() {
  if (!open_) return;
  std::fputc('\n', out_);
  std::fflush(out_);
  open_ = false;
}

}  // namespace paircast
