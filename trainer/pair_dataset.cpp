#include "trainer/pair_dataset.h"

#include <fcntl.h>
#include <glob.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace fs = std::filesystem;

namespace {

std::vector<std::string> expandPatterns(const std::vector<std::string>& patterns) {
  std::vector<std::string> files;
  for (const auto& p : patterns) {
    glob_t g{};
    if (::glob(p.c_str(), 0, nullptr, &g) == 0) {
      for (size_t i = 0; i < g.gl_pathc; ++i) files.push_back(g.gl_pathv[i]);
    } else if (fs::exists(p)) {
      files.push_back(p);
    } else {
      globfree(&g);
      throw Error(p, "no shard matches");
    }
    globfree(&g);
  }
  return files;
}

uint64_t octal(const char* p, size_t n) {
  uint64_t v = 0;
  for (size_t i = 0; i < n && p[i]; ++i) {
    if (p[i] == ' ') continue;
    if (p[i] < '0' || p[i] > '7') return UINT64_MAX;
    v = v * 8 + (p[i] - '0');
  }
  return v;
}

std::vector<unsigned char> readRange(const std::string& file, uint64_t offset, uint64_t length) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw Error(file, "cannot open");
  std::vector<unsigned char> data(length);
  uint64_t done = 0;
  while (done < length) {
    const ssize_t n =
        ::pread(fd, data.data() + done, length - done, static_cast<off_t>(offset + done));
    if (n <= 0) {
      ::close(fd);
      throw Error(file, "short read (file changed or truncated)");
    }
    done += static_cast<uint64_t>(n);
  }
  ::close(fd);
  return data;
}

// The view number of a shard member name after its key ("3.jpg" -> 3), or 0 when the member
// is not a view (K.json, K.1.depth.exr, K.01.jpg).
int viewNumber(const std::string& member) {
  constexpr size_t kMaxDigits = 6;
  const size_t dot = member.find('.');
  if (dot == 0 || dot > kMaxDigits || member.compare(dot, std::string::npos, ".jpg") != 0 ||
      member[0] == '0')
    return 0;
  int k = 0;
  for (size_t i = 0; i < dot; ++i) {
    if (member[i] < '0' || member[i] > '9') return 0;
    k = k * 10 + (member[i] - '0');
  }
  return k;
}

}  // namespace

PairDataset PairDataset::fromShards(const std::vector<std::string>& patterns) {
  PairDataset ds;
  for (const auto& file : expandPatterns(patterns)) {
    const uint64_t fileSize = fs::file_size(file);
    std::ifstream in(file, std::ios::binary);
    if (!in) throw Error(file, "cannot open shard");
    std::map<std::string, std::map<int, Member>> views;  // key -> view number -> member
    std::vector<std::string> order;
    uint64_t pos = 0;
    char h[512];
    bool truncated = false;
    while (pos + 512 <= fileSize) {
      in.seekg(static_cast<std::streamoff>(pos));
      if (!in.read(h, 512)) break;
      if (h[0] == '\0') break;  // end-of-archive blocks
      const std::string name(h, strnlen(h, 100));
      const uint64_t size = octal(h + 124, 12);
      if (size == UINT64_MAX || pos + 512 + size > fileSize) {
        truncated = true;
        break;
      }
      const char type = h[156];
      const size_t dot = name.find('.');
      if ((type == '0' || type == '\0') && dot != std::string::npos &&
          name.find('/') == std::string::npos) {
        const std::string key = name.substr(0, dot);
        const int k = viewNumber(name.substr(dot + 1));
        if (k > 0 && size > 0) {  // an empty member counts as missing
          if (!views.count(key)) order.push_back(key);
          views[key][k] = Member{file, pos + 512, size, name};
        }
      }
      pos += 512 + (size + 511) / 512 * 512;
    }
    if (truncated)
      std::fprintf(stderr, "pretrain: warning: %s is truncated; its whole samples are used\n",
                   file.c_str());
    size_t incomplete = 0;
    for (const auto& key : order) {
      const auto& members = views[key];
      if (!members.count(1) || members.size() < 2) {
        ++incomplete;
        continue;
      }
      Sample sample{key, members.at(1), {}};
      for (const auto& [k, m] : members)
        if (k != 1) sample.others.push_back(m);
      ds.samples_.push_back(std::move(sample));
    }
    // A truncated shard's last sample is cut by the truncation, reported above.
    if (incomplete > (truncated ? 1u : 0u))
      std::fprintf(stderr,
                   "pretrain: warning: %s: %zu samples lack view 1 (KEY.1.jpg) or any other "
                   "view; skipped\n",
                   file.c_str(), incomplete);
  }
  if (ds.samples_.empty())
    throw Error(patterns.empty() ? "--data" : patterns[0], "no complete pair in the shards");
  return ds;
}

PairDataset PairDataset::fromCrocoDir(const std::string& dir) {
  const std::string list = (fs::path(dir) / "pairs.txt").string();
  std::ifstream in(list);
  if (!in) throw Error(list, "cannot read pairs.txt (is this a CroCo pairs folder?)");
  PairDataset ds;
  std::map<std::string, size_t> byFirst;  // im1 -> its sample
  std::string a, b;
  while (in >> a >> b) {
    const Member other{(fs::path(dir) / b).string(), 0, 0, ""};
    auto [it, added] = byFirst.emplace(a, ds.samples_.size());
    if (added) {
      ds.samples_.push_back({a, Member{(fs::path(dir) / a).string(), 0, 0, ""}, {other}});
      continue;
    }
    auto& others = ds.samples_[it->second].others;
    const bool listed = std::any_of(others.begin(), others.end(),
                                    [&](const Member& m) { return m.file == other.file; });
    if (!listed) others.push_back(other);  // a repeated line would weigh its view twice
  }
  if (ds.samples_.empty()) throw Error(list, "lists no pair");
  return ds;
}

void PairDataset::restrictTo(const std::string& keysFile) {
  std::ifstream in(keysFile);
  if (!in) throw Error(keysFile, "cannot read the key list");
  std::map<std::string, bool> wanted;  // key -> found
  std::string line;
  while (std::getline(in, line)) {
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (!line.empty()) wanted.emplace(line, false);
  }
  if (wanted.empty()) throw Error(keysFile, "lists no key");
  std::vector<Sample> kept;
  for (auto& p : samples_) {
    auto it = wanted.find(p.key);
    if (it == wanted.end() || it->second) continue;  // not listed, or a duplicate
    it->second = true;
    kept.push_back(std::move(p));
  }
  for (const auto& [key, found] : wanted)
    if (!found) throw Error(keysFile, "lists key '" + key + "', which is not in the data");
  samples_ = std::move(kept);
}

std::pair<Image8, Image8> PairDataset::load(size_t i, uint64_t draw) const {
  const Sample& s = samples_.at(i);
  auto one = [&](const Member& m) {
    if (m.length == 0) return readImage8(m.file);
    const auto bytes = readRange(m.file, m.offset, m.length);
    return decodeImage8(bytes.data(), bytes.size(), m.file + ":" + m.name);
  };
  return {one(s.first), one(s.others[draw % s.others.size()])};
}

std::string PairDataset::describe(size_t i) const {
  return samples_.at(i).first.file + ":" + samples_.at(i).key;
}

}  // namespace paircast
