// Fuzz entry points for dataset/: tar shards through readShard, sample records through
// parseSampleRecord. See fuzz_inputs.h.
#pragma once

#include <nlohmann/json.hpp>
#include <stdexcept>

#include "dataset/shard.h"
#include "fuzz/fuzz_inputs.h"

namespace paircast::fuzz {

inline bool runShardInput(std::string_view bytes, const std::string& dir = scratchDir()) {
  const std::string path = writeInput(bytes, dir, "input.tar");
  ShardReadOptions options;
  options.maxEntryBytes = 1 << 20;
  return acceptedOrRefused([&] {
    // readShard promises that every delivered sample's record parses: a broken promise is a
    // finding, not a refusal, hence logic_error.
    readShard(
        path,
        [&](ShardSample&& s) {
          if (!acceptedOrRefused([&] { parseSampleRecord(s.record, path + ":" + s.key); }))
            throw std::logic_error("readShard delivered a sample whose record does not parse");
        },
        [](const std::string&) {}, options);
  });
}

inline bool runSampleJsonInput(std::string_view bytes) {
  return acceptedOrRefused([&] {
    const nlohmann::json j = nlohmann::json::parse(bytes.begin(), bytes.end(), nullptr, false);
    if (j.is_discarded()) throw Error("input", "not valid JSON");
    parseSampleRecord(j, "input");
  });
}

}  // namespace paircast::fuzz
