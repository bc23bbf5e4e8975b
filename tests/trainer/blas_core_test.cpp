#include "util/blas_core.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "test_pairs.h"
#include "test_paths.h"
#include "util/atomic_file.h"

namespace paircast {
namespace {

namespace fs = std::filesystem;

TEST(CpuFlags, FirstProcessorsFlagsLine) {
  const CpuFlags f = cpuFlagsFrom(
      "processor\t: 0\nvendor_id\t: AuthenticAMD\nflags\t\t: fpu avx2 fma avx512_bf16\n"
      "processor\t: 1\nflags\t\t: fpu\n");
  EXPECT_EQ(f, (CpuFlags{"fpu", "avx2", "fma", "avx512_bf16"}));
  EXPECT_TRUE(cpuFlagsFrom("processor\t: 0\nFeatures\t: fp asimd\n").empty());  // aarch64
  EXPECT_EQ(bf16UnitsFlag({"avx512_bf16", "amx_bf16"}), "amx_bf16");
  EXPECT_EQ(bf16UnitsFlag({"avx512f"}), "");
}

TEST(BlasCore, ExpectedCoreAndItsAge) {
  const CpuFlags avx512 = {"pni",     "avx",      "avx2",     "fma",
                           "avx512f", "avx512bw", "avx512vl", "avx512dq"};
  CpuFlags bf16 = avx512;
  bf16.insert("avx512_bf16");
  EXPECT_EQ(expectedBlasCore(bf16), "Cooperlake");
  EXPECT_EQ(expectedBlasCore(avx512), "SkylakeX");
  EXPECT_EQ(expectedBlasCore({"pni", "avx", "avx2", "fma"}), "Haswell");
  EXPECT_EQ(expectedBlasCore({"pni", "avx"}), "Sandybridge");
  EXPECT_EQ(expectedBlasCore({"pni"}), "Prescott");
  EXPECT_EQ(expectedBlasCore({}), "");
  EXPECT_TRUE(olderBlasCore("Prescott", "SkylakeX"));
  EXPECT_TRUE(olderBlasCore("Haswell", "Cooperlake"));
  EXPECT_TRUE(olderBlasCore("ZEN", "SkylakeX"));  // Zen runs Haswell's kernels
  EXPECT_FALSE(olderBlasCore("Zen", "Haswell"));
  EXPECT_FALSE(olderBlasCore("SapphireRapids", "Cooperlake"));
  EXPECT_FALSE(olderBlasCore("Cooperlake", "Cooperlake"));
  EXPECT_FALSE(olderBlasCore("Unknown", "SkylakeX"));  // a core this does not know: no action
  EXPECT_FALSE(olderBlasCore("Haswell", ""));
}

struct ToolRun {
  int rc = -1;
  std::string output;  // stdout and stderr
  nlohmann::json summary;
};

// pretrain for one step of 32x32 pairs, under the environment `env` ("NAME=value ...") with
// OpenBLAS's and the check's own variables cleared first and the CPU's flags faked to an AVX2
// one (expected core: Haswell).
ToolRun pretrainWith(const std::string& env, const std::string& out) {
  const std::string cpuinfo = out + ".cpuinfo";
  writeFileAtomic(cpuinfo, "processor\t: 0\nflags\t\t: fpu pni avx avx2 fma\n");
  const std::string cmd =
      "env -u OPENBLAS_CORETYPE -u PAIRCAST_OPENBLAS_REEXEC -u PAIRCAST_OPENBLAS_CHECK "
      "-u PAIRCAST_FAKE_BLAS_CORE PAIRCAST_CPUINFO=" +
      cpuinfo + " " + env + " " + PAIRCAST_BINARY_DIR + "/tools/pretrain --data '" +
      testing::roomPairs() +
      "/pairs-*.tar' --img-size 32 --batch-size 4 --max-steps 1 --amp none " + "--out " + out +
      " --quiet 2>&1";
  ToolRun r;
  std::FILE* p = popen(cmd.c_str(), "r");
  for (int ch; (ch = std::fgetc(p)) != EOF;) r.output.push_back(static_cast<char>(ch));
  const int status = pclose(p);
  r.rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(out + "/summary.json");
  if (in) r.summary = nlohmann::json::parse(in)["openblas_core"];
  return r;
}

// A mismatch faked on an AVX2 CPU: OpenBLAS reads as Prescott's kernels until the re-execution,
// which sets OPENBLAS_CORETYPE=Haswell; a user's OPENBLAS_CORETYPE is kept, without a warning.
TEST(BlasCore, OlderCoreIsFixedByRunningAgainOrWarned) {
  if (loadedBlasCore().empty()) GTEST_SKIP() << "LibTorch runs on no OpenBLAS here";
  const CpuFlags& real = cpuFlags();
  if (!real.count("avx2") || !real.count("fma"))
    GTEST_SKIP() << "this CPU cannot run OpenBLAS's Haswell kernels, which the fake CPU asks for";
  const std::string dir = testing::scratchDir("blas_core");

  const ToolRun fixed = pretrainWith("PAIRCAST_FAKE_BLAS_CORE=Prescott", dir + "/fixed");
  ASSERT_EQ(fixed.rc, 0) << fixed.output;
  EXPECT_EQ(fixed.summary["name"], "Haswell") << fixed.output;
  EXPECT_EQ(fixed.summary["expected"], "Haswell");
  EXPECT_EQ(fixed.summary["action"], "re-executed");
  EXPECT_EQ(fixed.output.find("warning: OpenBLAS"), std::string::npos) << fixed.output;

  const ToolRun user = pretrainWith("OPENBLAS_CORETYPE=Prescott", dir + "/user");
  ASSERT_EQ(user.rc, 0) << user.output;
  EXPECT_EQ(user.summary["name"], "Prescott");
  EXPECT_EQ(user.summary["action"], "kept OPENBLAS_CORETYPE=Prescott");
  EXPECT_EQ(user.output.find("warning: OpenBLAS"), std::string::npos) << user.output;

  const ToolRun off =
      pretrainWith("PAIRCAST_OPENBLAS_CHECK=0 PAIRCAST_FAKE_BLAS_CORE=Prescott", dir + "/off");
  ASSERT_EQ(off.rc, 0) << off.output;
  EXPECT_EQ(off.summary["action"], "off");
  EXPECT_EQ(off.output.find("warning: OpenBLAS"), std::string::npos) << off.output;
}

}  // namespace
}  // namespace paircast
