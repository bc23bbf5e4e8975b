#include "util/progress_line.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

namespace paircast {
namespace {

// Runs `body` on a progress line writing to a temporary file, and returns what it wrote.
template <typename F>
std::string written(bool inPlace, double logInterval, F body) {
  std::FILE* f = std::tmpfile();
  {
    ProgressLine line(f, inPlace, logInterval);
    body(line);
  }
  std::string out(static_cast<size_t>(std::ftell(f)), '\0');
  std::rewind(f);
  out.resize(std::fread(out.data(), 1, out.size(), f));
  std::fclose(f);
  return out;
}

TEST(ProgressLine, ALogGetsALineAnIntervalAndTheLastOne) {
  const std::string out = written(false, 60, [](ProgressLine& p) {
    EXPECT_TRUE(p.due());
    p.show("step 1");
    EXPECT_FALSE(p.due());
    for (int i = 2; i < 100; ++i) p.show("step " + std::to_string(i));  // within the interval
    p.show("step 100", /*last=*/true);
  });
  EXPECT_EQ(out, "step 1\nstep 100\n");
  const std::string every = written(false, 0.02, [](ProgressLine& p) {
    p.show("a");
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
    EXPECT_TRUE(p.due());
    p.show("b");
  });
  EXPECT_EQ(every, "a\nb\n");
}

TEST(ProgressLine, ATerminalLineIsRedrawnInPlace) {
  const std::string out = written(true, 60, [](ProgressLine& p) {
    p.show("step 1");
    p.show("step 2");  // within the terminal interval: not drawn
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    p.show("step 3");
    p.breakLine();  // a warning follows on its own line
    p.breakLine();  // nothing open: nothing written
    p.show("step 4", /*last=*/true);
  });
  EXPECT_EQ(out, "\rstep 1\033[K\rstep 3\033[K\n\rstep 4\033[K\n");
  // An open line is ended when the progress line goes away.
  EXPECT_EQ(written(true, 60, [](ProgressLine& p) { p.show("x"); }), "\rx\033[K\n");
}

TEST(ProgressLine, DisabledPrintsNothing) {
  ::testing::internal::CaptureStderr();
  {
    ProgressLine off(false);
    EXPECT_FALSE(off.due());
    off.show("never", /*last=*/true);
  }
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
}

}  // namespace
}  // namespace paircast
