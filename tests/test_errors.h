// Checks on the errors users see for bad input.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "util/error.h"

namespace paircast::testing {

// Runs `read`, which must refuse `path` with a paircast::Error: one line that names the file.
// Returns its message ("" after a failure when nothing was thrown).
template <class F>
std::string refusalOf(const std::string& path, F&& read) {
  try {
    read();
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << "one line: " << what;
    return what;
  }
  ADD_FAILURE() << path << " was accepted";
  return "";
}

}  // namespace paircast::testing
