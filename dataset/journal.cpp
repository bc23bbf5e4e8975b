#include "dataset/journal.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "util/error.h"

namespace paircast {
namespace {

// fsync after this many appended lines, or this many seconds, whichever comes first.
constexpr size_t kSyncLines = 256;
constexpr double kSyncSeconds = 2.0;
// Opening reads the journal this many bytes at a time (a line longer than that grows the block).
constexpr size_t kReadBlock = size_t(1) << 22;
// Bytes of a short record, to size the index before reading.
constexpr size_t kTypicalLine = 96;

std::string lastError() {
  return std::strerror(errno);
}

}  // namespace

Journal::Journal(const std::string& path, std::string (*keyOf)(const nlohmann::json&),
                 bool (*mark)(const nlohmann::json&))
    : path_(path), keyOf_(keyOf), mark_(mark), lastSync_(SteadyClock::now()) {
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw Error(path, "cannot open the journal: " + lastError());
  load();
}

Journal::~Journal() {
  if (fd_ < 0) return;
  if (unsynced_) ::fdatasync(fd_);
  ::close(fd_);
}

// Reads every whole line, a block at a time; a torn tail (no newline) is cut off so that appends
// start clean.
void Journal::load() {
  index_.clear();
  const off_t end = ::lseek(fd_, 0, SEEK_END);
  if (end < 0) throw Error(path_, "cannot read the journal: " + lastError());
  index_.reserve(static_cast<size_t>(end) / kTypicalLine);
  std::string block;
  uint64_t pos = 0;  // start of the first line not yet indexed
  while (pos + block.size() < static_cast<uint64_t>(end)) {
    const size_t want = std::min<uint64_t>(kReadBlock, end - pos - block.size());
    const size_t had = block.size();
    block.resize(had + want);
    const ssize_t n = ::pread(fd_, block.data() + had, want, static_cast<off_t>(pos + had));
    if (n <= 0) throw Error(path_, "cannot read the journal: " + lastError());
    block.resize(had + static_cast<size_t>(n));
    const size_t used = indexLines(block, pos);
    block.erase(0, used);
    pos += used;
  }
  size_ = indexed_ = pos;
  if (size_ != static_cast<uint64_t>(end) && ::ftruncate(fd_, static_cast<off_t>(size_)) != 0)
    throw Error(path_, "cannot cut the journal's torn last line: " + lastError());
}

size_t Journal::indexLines(const std::string& block, uint64_t offset) {
  size_t pos = 0;
  for (size_t nl; (nl = block.find('\n', pos)) != std::string::npos; pos = nl + 1) {
    const auto record =
        nlohmann::json::parse(block.begin() + pos, block.begin() + nl, nullptr, false);
    const std::string key = record.is_object() ? keyOf_(record) : std::string();
    if (!key.empty())
      index_[key] = {offset + pos, static_cast<uint32_t>(nl - pos), mark_ && mark_(record)};
  }
  return pos;
}

Journal::Has Journal::has(const std::string& key) const {
  const auto it = index_.find(key);
  if (it == index_.end()) return Has::kNo;
  return it->second.marked ? Has::kMarked : Has::kYes;
}

nlohmann::json Journal::find(const std::string& key) const {
  const auto it = index_.find(key);
  if (it == index_.end()) return nullptr;
  std::string line(it->second.length, '\0');
  const ssize_t n = ::pread(fd_, line.data(), line.size(), static_cast<off_t>(it->second.offset));
  if (n != static_cast<ssize_t>(line.size()))
    throw Error(path_, "cannot read the journal: " + lastError());
  return nlohmann::json::parse(line, nullptr, false);
}

void Journal::append(const nlohmann::json& record) {
  const std::string line = record.dump() + "\n";
  size_t done = 0;
  while (done < line.size()) {
    const ssize_t n =
        ::pwrite(fd_, line.data() + done, line.size() - done, static_cast<off_t>(size_ + done));
    if (n <= 0) {
      const std::string why = n < 0 ? lastError() : "short write";
      if (::ftruncate(fd_, static_cast<off_t>(size_)) != 0) {
      }  // best effort: the next open cuts a torn line anyway
      throw Error(path_, "cannot append to the journal: " + why);
    }
    done += static_cast<size_t>(n);
  }
  size_ += line.size();
  if (++unsynced_ >= kSyncLines || secondsSince(lastSync_) >= kSyncSeconds) sync();
}

void Journal::sync() {
  if (unsynced_ && ::fdatasync(fd_) != 0)
    throw Error(path_, "cannot flush the journal to disk: " + lastError());
  unsynced_ = 0;
  lastSync_ = SteadyClock::now();
}

void Journal::reopen() {
  sync();
  if (size_ != indexed_) load();
}

}  // namespace paircast
