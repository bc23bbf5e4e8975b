// Checks on the errors users see for bad input.
#pragma once

#include <gtest/gtest.h>

#include <exception>
#include <initializer_list>
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

// Whether `run` throws a paircast::Error whose message holds each of `parts` (the file it names,
// the words of the throw site); for EXPECT_ERROR_CONTAINS.
template <class F>
::testing::AssertionResult errorContains(F&& run, std::initializer_list<std::string> parts) {
  std::string what;
  try {
    run();
    return ::testing::AssertionFailure() << "nothing was thrown";
  } catch (const Error& e) {
    what = e.what();
  } catch (const std::exception& e) {
    return ::testing::AssertionFailure()
           << "threw another exception than paircast::Error: " << e.what();
  } catch (...) {
    return ::testing::AssertionFailure() << "threw another exception than paircast::Error";
  }
  for (const std::string& part : parts)
    if (what.find(part) == std::string::npos)
      return ::testing::AssertionFailure() << "the message lacks \"" << part << "\": " << what;
  return ::testing::AssertionSuccess() << what;
}

}  // namespace paircast::testing

// EXPECT_ERROR_CONTAINS(statement, part, ...): `statement` throws a paircast::Error whose
// message holds every part (std::string or string literal), such as the file and the reason.
#define EXPECT_ERROR_CONTAINS(statement, ...) \
  EXPECT_TRUE(::paircast::testing::errorContains([&] { statement; }, {__VA_ARGS__}))
