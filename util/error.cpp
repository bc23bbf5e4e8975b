#include "util/error.h"

namespace paircast {

void checkFailed(const char* file, int line, const char* expr, const std::string& msg) {
  std::ostringstream os;
  os << "internal check failed at " << file << ":" << line << ": " << expr;
  if (!msg.empty()) os << " (" << msg << ")";
  // Thrown rather than aborted so that tools can report it on one line and exit non-zero.
  throw std::logic_error(os.str());
}

}  // namespace paircast
