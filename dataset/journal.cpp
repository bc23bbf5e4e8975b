#include "dataset/journal.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "util/error.h"

namespace paircast {
namespace {

// fsync after this many appended lines, or this many seconds, whichever comes first.
constexpr size_t kSyncLines = 256;
constexpr double kSyncSeconds = 2.0;

std::string lastError() {
  return std::strerror(errno);
}

}  // namespace

Journal::Journal(const std::string& path, std::string (*keyOf)(const nlohmann::json&))
    : path_(path), keyOf_(keyOf), lastSync_(SteadyClock::now()) {
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw Error(path, "cannot open the journal: " + lastError());
  load();
}

Journal::~Journal() {
  if (fd_ < 0) return;
  if (unsynced_) ::fdatasync(fd_);
  ::close(fd_);
}

// Reads every whole line; a torn tail (no newline) is cut off so that appends start clean.
void Journal::load() {
  index_.clear();
  const off_t end = ::lseek(fd_, 0, SEEK_END);
  if (end < 0) throw Error(path_, "cannot read the journal: " + lastError());
  std::string data(static_cast<size_t>(end), '\0');
  size_t got = 0;
  while (got < data.size()) {
    const ssize_t n = ::pread(fd_, data.data() + got, data.size() - got, static_cast<off_t>(got));
    if (n <= 0) throw Error(path_, "cannot read the journal: " + lastError());
    got += static_cast<size_t>(n);
  }
  size_t pos = 0;
  for (size_t nl; (nl = data.find('\n', pos)) != std::string::npos; pos = nl + 1) {
    const auto record =
        nlohmann::json::parse(data.begin() + pos, data.begin() + nl, nullptr, false);
    const std::string key = record.is_object() ? keyOf_(record) : std::string();
    if (!key.empty()) index_[key] = {pos, static_cast<uint32_t>(nl - pos)};
  }
  size_ = pos;
  if (size_ != data.size() && ::ftruncate(fd_, static_cast<off_t>(size_)) != 0)
    throw Error(path_, "cannot cut the journal's torn last line: " + lastError());
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
  load();
}

}  // namespace paircast
