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

#include "shard/shard_index.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace fs = std::filesystem;

std::vector<std::string> expandShardPatterns(const std::vector<std::string>& patterns) {
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

namespace {

// The whole file, or [offset, offset + length) of it.
std::vector<unsigned char> readMember(const std::string& file, uint64_t offset, uint64_t length) {
  if (length == 0) {
    const std::string bytes = readFile(file);
    return {bytes.begin(), bytes.end()};
  }
  return readFileRange(file, offset, length);
}

void warn(const std::string& message) {
  std::fprintf(stderr, "pretrain: warning: %s\n", message.c_str());
}

}  // namespace

PairDataset PairDataset::fromShards(const std::vector<std::string>& patterns) {
  PairDataset ds;
  for (const auto& file : expandShardPatterns(patterns)) {
    const ShardIndex index = ShardIndex::open(file, warn);
    index.warnOfDamage(warn);
    size_t single = 0;
    for (const IndexedSample& s : index.samples()) {
      auto member = [&](size_t k) {
        return Member{file, s.image[k].offset, s.image[k].size,
                      memberName(s.key, MemberKind::kImage, static_cast<int>(k) + 1)};
      };
      if (s.image.size() < 2) {
        ++single;
        continue;
      }
      Sample sample{s.key, member(0), {}};
      for (size_t k = 1; k < s.image.size(); ++k) sample.others.push_back(member(k));
      ds.samples_.push_back(std::move(sample));
    }
    if (single)
      warn(file + ": " + std::to_string(single) + " samples have one view, no pair; skipped");
  }
  if (ds.samples_.empty())
    throw Error(patterns.empty() ? "shards" : patterns[0], "no complete pair in the shards");
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

std::pair<EncodedImage, EncodedImage> PairDataset::encoded(size_t i, uint64_t draw) const {
  const Sample& s = samples_.at(i);
  auto one = [&](const Member& m) {
    return EncodedImage{readMember(m.file, m.offset, m.length),
                        m.name.empty() ? m.file : m.file + ":" + m.name};
  };
  return {one(s.first), one(s.others[draw % s.others.size()])};
}

std::pair<Image8, Image8> PairDataset::load(size_t i, uint64_t draw) const {
  auto [a, b] = encoded(i, draw);
  return {decodeImage8(a.bytes.data(), a.bytes.size(), a.name),
          decodeImage8(b.bytes.data(), b.bytes.size(), b.name)};
}

std::string PairDataset::describe(size_t i) const {
  return samples_.at(i).first.file + ":" + samples_.at(i).key;
}

}  // namespace paircast
