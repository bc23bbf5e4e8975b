// Training data for tests: pairs generated once per test process.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

#include "dataset/generate_job.h"
#include "test_paths.h"

namespace paircast::testing {

// 32 pairs of the shipped room at 64x64, in shards of 16 and in CroCo's layout. One folder per
// test process (ctest runs the tests of a file in parallel processes), removed at its exit.
inline const std::string& roomPairs() {
  static const std::string dir = [] {
    const std::string d = (std::filesystem::path(::testing::TempDir()) / "paircast" /
                           ("room_pairs." + std::to_string(getpid())))
                              .string();
    std::filesystem::remove_all(d);
    GenerateConfig g;
    g.scenes = {sourceDir() + "/scenes/room/room.obj"};
    g.out = d;
    g.pairsPerScene = 32;
    g.pair.resolution = 64;
    g.shardSize = 16;
    g.croco = true;
    g.progress = false;
    runGenerate(g);
    return d;
  }();
  static const struct Cleanup {
    ~Cleanup() { std::filesystem::remove_all(dir); }
  } cleanup;
  return dir;
}

}  // namespace paircast::testing
