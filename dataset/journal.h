// An append-only journal of JSON records, one per line, that replaces a file per pair: a job's
// bookkeeping is one file, whatever its size. Lines are written as they come and fsynced in
// batches (and on sync()). A killed writer can leave a torn last line: opening the journal cuts it
// off. Records are found by key: the last line written for a key wins.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <unordered_map>

#include "util/timer.h"

namespace paircast {

class Journal {
 public:
  // Opens (creating) the journal at `path` and indexes its records by `keyOf(record)`, noting
  // which ones `mark` (optional) holds true of. Lines that are not JSON objects, or that keyOf
  // gives "", are ignored. Throws paircast::Error naming the file.
  Journal(const std::string& path, std::string (*keyOf)(const nlohmann::json&),
          bool (*mark)(const nlohmann::json&) = nullptr);
  ~Journal();
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;

  // The record of `key` as it was when the journal was opened or last reopen()ed, or null.
  nlohmann::json find(const std::string& key) const;
  // Whether `key` has a record, as find() sees them, and whether it is marked, without reading it.
  enum class Has { kNo, kYes, kMarked };
  Has has(const std::string& key) const;
  bool contains(const std::string& key) const { return has(key) != Has::kNo; }

  // Appends one record. Not thread-safe: one writer. Throws paircast::Error on a failed write (a
  // full disk included); the journal then ends at the last whole line.
  void append(const nlohmann::json& record);
  // fsyncs what was appended.
  void sync();
  // Re-reads the index, so that find() sees the records appended since (if any).
  void reopen();

  const std::string& path() const { return path_; }

 private:
  struct Span {
    uint64_t offset;
    uint32_t length;
    bool marked;
  };
  void load();
  // Indexes the whole lines of `block`, which starts at byte `offset`; returns the bytes used.
  size_t indexLines(const std::string& block, uint64_t offset);
  std::string path_;
  std::string (*keyOf_)(const nlohmann::json&);
  bool (*mark_)(const nlohmann::json&);
  int fd_ = -1;
  uint64_t size_ = 0;     // bytes of whole lines
  uint64_t indexed_ = 0;  // of which the index covers
  size_t unsynced_ = 0;
  SteadyClock::time_point lastSync_;
  std::unordered_map<std::string, Span> index_;
};

}  // namespace paircast
