#include "shard/shard_index.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>

#include "util/error.h"

namespace paircast {
namespace {

constexpr uint64_t kBlock = 512;
// A sample's JSON record: a few kilobytes for 99 views. A parse builds several times its bytes in
// nested containers, so a record past this is skipped unread.
constexpr uint64_t kMaxRecordBytes = 1ull << 20;

// An open file, closed on every path out.
struct Fd {
  int fd = -1;
  explicit Fd(const std::string& path) : fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC)) {}
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
};

bool readAt(int fd, void* out, uint64_t size, uint64_t offset) {
  uint64_t done = 0;
  while (done < size) {
    const ssize_t n =
        ::pread(fd, static_cast<char*>(out) + done, size - done, static_cast<off_t>(offset + done));
    if (n <= 0) return false;
    done += static_cast<uint64_t>(n);
  }
  return true;
}

// A header's size field: octal digits, or GNU base-256 when the high bit is set. -1 when it is
// neither, negative, or beyond 2^62.
int64_t sizeField(const unsigned char* f) {
  if (f[0] & 0x80) {
    if (f[0] == 0xff) return -1;  // negative
    uint64_t v = f[0] & 0x7f;
    for (int i = 1; i < 12; ++i) {
      if (v >> 54) return -1;
      v = (v << 8) | f[i];
    }
    return v >> 62 ? -1 : static_cast<int64_t>(v);
  }
  uint64_t v = 0;
  for (int i = 0; i < 12 && f[i] && f[i] != ' '; ++i) {
    if (f[i] < '0' || f[i] > '7' || (v >> 58)) return -1;
    v = v * 8 + (f[i] - '0');
  }
  return static_cast<int64_t>(v);
}

// The ustar checksum: the header's bytes with the checksum field read as spaces (tar tools
// differ on signed bytes, so both sums are accepted).
bool checksumMatches(const unsigned char* h) {
  uint64_t stored = 0;
  int digits = 0;
  for (int i = 148; i < 156 && h[i] && h[i] != ' '; ++i, ++digits) {
    if (h[i] < '0' || h[i] > '7') return false;
    stored = stored * 8 + (h[i] - '0');
  }
  if (digits == 0) return false;
  int64_t unsignedSum = 8 * ' ', signedSum = 8 * ' ';
  for (size_t i = 0; i < kBlock; ++i) {
    if (i >= 148 && i < 156) continue;
    unsignedSum += h[i];
    signedSum += static_cast<signed char>(h[i]);
  }
  return static_cast<int64_t>(stored) == unsignedSum || static_cast<int64_t>(stored) == signedSum;
}

std::string field(const unsigned char* h, size_t offset, size_t length) {
  const char* p = reinterpret_cast<const char*>(h) + offset;
  return std::string(p, strnlen(p, length));
}

// Names that could leave a folder they were extracted to, or that hold control characters.
bool unsafePath(const std::string& name) {
  return name.empty() || name[0] == '/' || name.find("..") != std::string::npos ||
         name.find('/') != std::string::npos || std::any_of(name.begin(), name.end(), [](char c) {
           return static_cast<unsigned char>(c) < 0x20 || c == 0x7f;
         });
}

// An entry name as it may appear in a one-line message: control bytes escaped, length capped.
std::string printable(const std::string& name) {
  std::string out;
  for (unsigned char c : name.substr(0, 200)) {
    if (c >= 0x20 && c != 0x7f) {
      out += static_cast<char>(c);
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      out += hex;
    }
  }
  return name.size() > 200 ? out + "..." : out;
}

// The "path" of a pax extended header's records ("<length> path=<value>\n" ...), or "".
std::string paxPath(const std::string& data) {
  size_t pos = 0;
  while (pos < data.size()) {
    const size_t space = data.find(' ', pos);
    if (space == std::string::npos) break;
    const size_t length = std::strtoull(data.c_str() + pos, nullptr, 10);
    // Written so that no length can overflow: a record holds at least its length, the space and
    // the newline, and lies inside the header.
    if (length <= space - pos + 1 || length > data.size() - pos) break;
    const std::string record = data.substr(space + 1, pos + length - space - 2);
    if (record.rfind("path=", 0) == 0) return record.substr(5);
    pos += length;
  }
  return {};
}

// The members of one sample as the headers list them, before its record is checked.
struct PendingSample {
  std::string key;
  Extent record;
  bool hasRecord = false;
  std::vector<Extent> member[kViewMemberKinds];  // by MemberKind, [view - 1]
};

// Walks the headers and groups members into samples; the record checks are the caller's.
class HeaderWalker {
 public:
  HeaderWalker(const std::string& path, int fd, uint64_t fileSize, const ShardIndex::Warn& warn,
               const ShardIndexOptions& options)
      : path_(path), fd_(fd), fileSize_(fileSize), warn_(warn), options_(options) {}

  // Calls onSample for each group of consecutive members with one key. Returns the damage, or
  // "" when the archive ends cleanly.
  std::string walk(const std::function<void(PendingSample&&)>& onSample) {
    const std::string damage = walkHeaders(onSample);
    flush(onSample);  // the last sample, or the one the damage cut (then reported incomplete)
    return damage;
  }

 private:
  std::string walkHeaders(const std::function<void(PendingSample&&)>& onSample) {
    unsigned char h[kBlock];
    std::string longName;
    while (pos_ + kBlock <= fileSize_) {
      if (!readAt(fd_, h, kBlock, pos_)) return "cannot read the header at byte " + at();
      if (std::all_of(h, h + kBlock, [](unsigned char c) { return c == 0; }))
        return {};  // the end-of-archive blocks
      if (!checksumMatches(h)) return "a damaged header at byte " + at();
      std::string name = field(h, 0, 100);
      const std::string prefix = field(h, 345, 155);
      if (std::memcmp(h + 257, "ustar", 5) == 0 && !prefix.empty()) name = prefix + "/" + name;
      if (!longName.empty()) name = std::move(longName), longName.clear();
      const int64_t size = sizeField(h + 124);
      if (size < 0 || static_cast<uint64_t>(size) > fileSize_)
        return "entry '" + printable(name) + "' claims " +
               (size < 0 ? std::string("an invalid size") : std::to_string(size) + " bytes") +
               ", more than the shard's " + std::to_string(fileSize_);
      const uint64_t data = pos_ + kBlock, length = static_cast<uint64_t>(size);
      if (data + length > fileSize_)
        return "entry '" + printable(name) + "' is cut off at byte " + std::to_string(fileSize_);
      pos_ = data + (length + kBlock - 1) / kBlock * kBlock;
      const char type = static_cast<char>(h[156]);
      if (type == 'L' || type == 'x') {  // the next entry's name (GNU long name, pax path)
        if (length > 65536) return "entry '" + printable(name) + "' has an oversized long name";
        std::string text(length, '\0');
        if (!readAt(fd_, text.data(), length, data)) return "cannot read byte " + at();
        longName = type == 'L' ? std::string(text.c_str()) : paxPath(text);
        continue;
      }
      if (type == 'g') continue;  // pax global header: nothing a sample needs
      add(name, type, Extent{data, length}, onSample);
    }
    return pos_ < fileSize_ ? "it ends inside a header at byte " + at()
                            : "it ends at byte " + at() + " without the end-of-archive blocks";
  }

  std::string at() const { return std::to_string(pos_); }
  void report(const std::string& msg) {
    if (warn_) warn_(path_ + ": " + msg);
  }

  void add(const std::string& name, char type, Extent e,
           const std::function<void(PendingSample&&)>& onSample) {
    if (type != '0' && type != '\0' && type != '7') {
      report("entry '" + printable(name) + "' is a link or not a plain file, ignored");
      return;
    }
    if (unsafePath(name)) {
      report("entry '" + printable(name) + "' is not a plain file name, ignored");
      return;
    }
    if (e.size > options_.maxEntryBytes) {
      report("entry '" + printable(name) + "' has an invalid size (" + std::to_string(e.size) +
             " bytes, limit " + std::to_string(options_.maxEntryBytes) + "), ignored");
      return;
    }
    const size_t dot = name.find('.');
    if (dot == std::string::npos || dot == 0) {
      report("entry '" + printable(name) + "' has no key, ignored");
      return;
    }
    const std::string key = name.substr(0, dot);
    if (key != current_.key) {
      flush(onSample);
      current_.key = key;
    }
    const auto m = parseMemberName(name);
    if (!m || e.size == 0) return;  // other members are not ours; an empty one counts as missing
    if (m->kind == MemberKind::kRecord) {
      current_.record = e;
      current_.hasRecord = true;
      return;
    }
    auto& list = current_.member[static_cast<int>(m->kind)];
    if (list.size() < static_cast<size_t>(m->view)) list.resize(m->view);
    list[m->view - 1] = e;
  }

  void flush(const std::function<void(PendingSample&&)>& onSample) {
    if (!current_.key.empty()) onSample(std::move(current_));
    current_ = PendingSample{};
  }

  std::string path_;
  int fd_;
  uint64_t fileSize_, pos_ = 0;
  ShardIndex::Warn warn_;  // copies: callers may pass temporaries
  ShardIndexOptions options_;
  PendingSample current_;
};

// Every view has its image, and depth, masks and flow are there for every view or for none.
bool wholeViews(const std::vector<Extent>& list, int views, bool optional) {
  if (optional && list.empty()) return true;
  return list.size() == static_cast<size_t>(views) &&
         std::none_of(list.begin(), list.end(), [](const Extent& e) { return e.size == 0; });
}

// The size of the open shard `f`; throws naming it when it is missing or not a file.
uint64_t shardSize(const Fd& f, const std::string& path) {
  struct stat st {};
  if (f.fd < 0 || ::fstat(f.fd, &st) != 0 || !S_ISREG(st.st_mode))
    throw Error(path, errno == ENOENT ? "no such shard" : "cannot read shard");
  return static_cast<uint64_t>(st.st_size);
}

std::string damageMessage(const std::string& where) {
  return "shard is truncated or corrupt: " + where;
}

}  // namespace

Bytes readFileRange(const std::string& path, uint64_t offset, uint64_t size) {
  Fd f(path);
  if (f.fd < 0) throw Error(path, std::string("cannot open: ") + std::strerror(errno));
  Bytes data(size);
  if (!readAt(f.fd, data.data(), size, offset))
    throw Error(path, "short read at byte " + std::to_string(offset) +
                          " (the file changed or was truncated since it was indexed)");
  return data;
}

ShardIndex ShardIndex::open(const std::string& path, const Warn& warn,
                            const ShardIndexOptions& options) {
  Fd f(path);
  const uint64_t size = shardSize(f, path);
  ShardIndex index;
  index.path_ = path;
  auto report = [&](const std::string& msg) {
    if (warn) warn(path + ": " + msg);
  };
  HeaderWalker walker(path, f.fd, size, warn, options);
  const std::string damage = walker.walk([&](PendingSample&& p) {
    const std::string sample = "sample '" + printable(p.key) + "'";
    nlohmann::json json;
    if (p.hasRecord && p.record.size > kMaxRecordBytes)
      return report(sample + "'s record is " + std::to_string(p.record.size) + " bytes (at most " +
                    std::to_string(kMaxRecordBytes) + "), skipped");
    if (p.hasRecord) {
      Bytes bytes(p.record.size);
      if (readAt(f.fd, bytes.data(), bytes.size(), p.record.offset))
        json = nlohmann::json::parse(bytes.begin(), bytes.end(), nullptr, false);
      if (json.is_discarded()) json = nullptr;
    }
    if (json.is_object() && json.contains("paircast_shard_version"))
      checkShardVersion(json, path);  // a shard of another version is refused whole
    if (json.is_null()) return report(sample + " is incomplete, skipped");
    IndexedSample s;
    try {
      s.record = parseSampleRecord(json, sample);
    } catch (const Error& e) {
      return report(std::string(e.what()) + ", skipped");
    }
    const int V = s.record.views;
    if (!wholeViews(p.member[0], V, false) || !wholeViews(p.member[1], V, true) ||
        !wholeViews(p.member[2], V, true) || !wholeViews(p.member[3], V, true)) {
      const size_t found = std::max(
          {p.member[0].size(), p.member[1].size(), p.member[2].size(), p.member[3].size()});
      return report(found > static_cast<size_t>(V)
                        ? sample + " has members of " + std::to_string(found) +
                              " views but its record names " + std::to_string(V) + ", skipped"
                        : sample + " is incomplete, skipped");
    }
    s.key = std::move(p.key);
    s.json = std::move(json);
    s.image = std::move(p.member[0]);
    s.depth = std::move(p.member[1]);
    s.covisMask = std::move(p.member[2]);
    s.flow = std::move(p.member[3]);
    index.samples_.push_back(std::move(s));
  });
  if (!damage.empty()) index.damage_ = damageMessage(damage);
  return index;
}

void ShardIndex::warnOfDamage(const Warn& warn) const {
  if (damaged() && warn) warn(path_ + ": " + damage_ + "; its whole samples are used");
}

std::vector<std::string> ShardIndex::keys(const std::string& path) {
  Fd f(path);
  const uint64_t size = shardSize(f, path);
  std::vector<std::string> keys;
  HeaderWalker walker(path, f.fd, size, {}, {});
  const std::string damage = walker.walk([&](PendingSample&& p) {
    if (p.hasRecord && p.record.size > 0 && !p.member[0].empty()) keys.push_back(std::move(p.key));
  });
  if (!damage.empty()) throw Error(path, damageMessage(damage));
  return keys;
}

Bytes ShardIndex::read(const Extent& e) const {
  return readFileRange(path_, e.offset, e.size);
}

std::string ShardIndex::describe(size_t i, MemberKind kind, int view) const {
  return path_ + ": " + memberName(samples_.at(i).key, kind, view);
}

}  // namespace paircast
