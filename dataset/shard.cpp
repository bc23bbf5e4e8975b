#include "dataset/shard.h"

#include <archive.h>
#include <archive_entry.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>

#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {
namespace fs = std::filesystem;

std::string sanitizeName(const std::string& name) {
  std::string out;
  for (char c : name)
    out += (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_') ? c : '_';
  return out.empty() ? "scene" : out;
}

std::string sampleKey(const std::string& scene, uint64_t index) {
  char idx[32];
  std::snprintf(idx, sizeof idx, "%08llu", static_cast<unsigned long long>(index));
  return sanitizeName(scene) + "-" + idx;
}

nlohmann::json sampleRecord(const PairSample& s) {
  nlohmann::json j;
  j["paircast_shard_version"] = kShardVersion;
  j["scene"] = s.scene;
  j["index"] = s.index;
  j["seed"] = s.seed;
  j["camera1"] = cameraToJson(s.camera[0]);
  j["camera2"] = cameraToJson(s.camera[1]);
  j["covis"] = s.covis.covis;
  j["v_ij"] = s.covis.v_ij;
  j["v_ji"] = s.covis.v_ji;
  j["valid_fraction1"] = s.covis.valid_i;
  j["valid_fraction2"] = s.covis.valid_j;
  j["candidates"] = s.candidateCovis.size();
  return j;
}

namespace {

double ratioField(const nlohmann::json& record, const char* key, const std::string& source) {
  if (!record.contains(key) || !record.at(key).is_number())
    throw Error(source, std::string("record has no number '") + key + "'");
  const double v = record.at(key).get<double>();
  if (!(v >= 0 && v <= 1)) throw Error(source, std::string("'") + key + "' is not in [0, 1]");
  return v;
}

}  // namespace

SampleRecord parseSampleRecord(const nlohmann::json& record, const std::string& source) {
  if (!record.is_object()) throw Error(source, "record is not a JSON object");
  const auto version = record.find("paircast_shard_version");
  if (version == record.end() || !version->is_number_integer() ||
      version->get<int64_t>() != kShardVersion)
    throw Error(source, "has an unsupported version (paircast_shard_version " +
                            (version == record.end() ? std::string("missing") : version->dump()) +
                            ", expected " + std::to_string(kShardVersion) +
                            "; regenerate the shard with generate_pairs)");
  SampleRecord r;
  if (!record.contains("scene") || !record.at("scene").is_string())
    throw Error(source, "record has no string 'scene'");
  r.scene = record.at("scene").get<std::string>();
  if (!record.contains("index") || !record.at("index").is_number_unsigned())
    throw Error(source, "record has no non-negative integer 'index'");
  r.index = record.at("index").get<uint64_t>();
  const char* cameraKeys[2] = {"camera1", "camera2"};
  for (int k = 0; k < 2; ++k) {
    if (!record.contains(cameraKeys[k]))
      throw Error(source, std::string("record has no '") + cameraKeys[k] + "'");
    r.camera[k] = cameraFromJson(record.at(cameraKeys[k]), source + " " + cameraKeys[k]);
  }
  r.covis = ratioField(record, "covis", source);
  r.v_ij = ratioField(record, "v_ij", source);
  r.v_ji = ratioField(record, "v_ji", source);
  return r;
}

EncodedPair encodePair(const PairSample& s, bool withDepth, int jpegQuality) {
  EncodedPair e;
  e.key = sampleKey(s.scene, s.index);
  for (int k = 0; k < 2; ++k) {
    e.jpeg[k] = encodeImage(s.rgb[k], "jpg", jpegQuality);
    if (withDepth) {
      PAIRCAST_CHECK_MSG(!s.depth[k].data.empty(), "depth requested but not kept");
      e.depthExr[k] = encodeExr(s.depth[k]);
    }
  }
  e.record = sampleRecord(s);
  return e;
}

ShardWriter::ShardWriter(const std::string& path) : path_(path), tmp_(tempPathFor(path)) {
  archive_ = archive_write_new();
  archive_write_set_format_ustar(archive_);
  archive_write_set_bytes_in_last_block(archive_, 1);
  if (archive_write_open_filename(archive_, tmp_.c_str()) != ARCHIVE_OK) {
    std::string why = archive_error_string(archive_) ? archive_error_string(archive_) : "?";
    archive_write_free(archive_);
    archive_ = nullptr;
    throw Error(path_, "cannot create shard: " + why);
  }
}

ShardWriter::~ShardWriter() {
  if (archive_) {
    archive_write_free(archive_);
    ::unlink(tmp_.c_str());
  }
}

void ShardWriter::addFile(const std::string& name, const void* data, size_t size) {
  archive_entry* entry = archive_entry_new();
  archive_entry_set_pathname(entry, name.c_str());
  archive_entry_set_size(entry, static_cast<la_int64_t>(size));
  archive_entry_set_filetype(entry, AE_IFREG);
  archive_entry_set_perm(entry, 0644);
  archive_entry_set_mtime(entry, 0, 0);
  archive_entry_set_uid(entry, 0);
  archive_entry_set_gid(entry, 0);
  const bool ok = archive_write_header(archive_, entry) == ARCHIVE_OK &&
                  archive_write_data(archive_, data, size) == static_cast<la_ssize_t>(size);
  archive_entry_free(entry);
  if (!ok) {
    std::string why =
        archive_error_string(archive_) ? archive_error_string(archive_) : "write failed";
    archive_write_free(archive_);
    archive_ = nullptr;
    ::unlink(tmp_.c_str());
    throw Error(path_, "cannot write shard: " + why);
  }
  bytes_ += size;
}

void ShardWriter::add(const EncodedPair& p) {
  PAIRCAST_CHECK(archive_ != nullptr);
  addFile(p.key + ".1.jpg", p.jpeg[0].data(), p.jpeg[0].size());
  addFile(p.key + ".2.jpg", p.jpeg[1].data(), p.jpeg[1].size());
  if (!p.depthExr[0].empty()) {
    addFile(p.key + ".1.depth.exr", p.depthExr[0].data(), p.depthExr[0].size());
    addFile(p.key + ".2.depth.exr", p.depthExr[1].data(), p.depthExr[1].size());
  }
  const std::string json = p.record.dump();
  addFile(p.key + ".json", json.data(), json.size());
  ++samples_;
}

void ShardWriter::close() {
  PAIRCAST_CHECK(archive_ != nullptr);
  const bool ok = archive_write_close(archive_) == ARCHIVE_OK;
  std::string why = !ok && archive_error_string(archive_) ? archive_error_string(archive_) : "";
  archive_write_free(archive_);
  archive_ = nullptr;
  if (!ok) {
    ::unlink(tmp_.c_str());
    throw Error(path_, "cannot finish shard: " + why);
  }
  commitFile(tmp_, path_);
}

namespace {

// Splits "key.member" at the first dot: WebDataset keys have no dots.
bool splitEntry(const std::string& name, std::string& key, std::string& member) {
  const size_t dot = name.find('.');
  if (dot == std::string::npos || dot == 0) return false;
  key = name.substr(0, dot);
  member = name.substr(dot + 1);
  return true;
}

// Names that could leave a folder they were extracted to, or that hold control characters.
bool unsafePath(const std::string& name) {
  return name.empty() || name[0] == '/' || name.find("..") != std::string::npos ||
         name.find('/') != std::string::npos || std::any_of(name.begin(), name.end(), [](char c) {
           return static_cast<unsigned char>(c) < 0x20 || c == 0x7f;
         });
}

// An entry name as it may appear in a one-line message: control bytes escaped, length capped.
std::string printableName(const std::string& name) {
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

struct ArchiveReader {
  archive* a;
  explicit ArchiveReader(const std::string& path) : a(archive_read_new()) {
    archive_read_support_format_tar(a);
    if (archive_read_open_filename(a, path.c_str(), 1 << 16) != ARCHIVE_OK) {
      std::string why = archive_error_string(a) ? archive_error_string(a) : "cannot open";
      archive_read_free(a);
      throw Error(path, "cannot read shard: " + why);
    }
  }
  ~ArchiveReader() { archive_read_free(a); }
};

}  // namespace

size_t readShard(const std::string& path, const std::function<void(ShardSample&&)>& onSample,
                 const std::function<void(const std::string&)>& onError,
                 const ShardReadOptions& options) {
  if (!fs::exists(path)) throw Error(path, "no such shard");
  std::error_code ec;
  const uint64_t shardBytes = fs::file_size(path, ec);
  if (ec) throw Error(path, "cannot read the shard's size: " + ec.message());
  ArchiveReader reader(path);
  size_t delivered = 0;
  ShardSample current;
  std::map<std::string, bool> seen;
  auto report = [&](const std::string& msg) {
    if (onError) onError(path + ": " + msg);
  };
  auto flush = [&]() {
    if (current.key.empty()) return;
    ShardSample s = std::move(current);
    current = ShardSample{};
    if (s.jpeg[0].empty() || s.jpeg[1].empty() || s.record.is_null()) {
      report("sample '" + printableName(s.key) + "' is incomplete, skipped");
      return;
    }
    try {
      parseSampleRecord(s.record, "sample '" + printableName(s.key) + "'");
    } catch (const Error& e) {
      report(std::string(e.what()) + ", skipped");
      return;
    }
    onSample(std::move(s));
    ++delivered;
  };
  archive_entry* entry = nullptr;
  while (true) {
    const int r = archive_read_next_header(reader.a, &entry);
    if (r == ARCHIVE_EOF) break;
    if (r != ARCHIVE_OK && r != ARCHIVE_WARN) {
      flush();
      throw Error(path,
                  std::string("shard is truncated or corrupt: ") +
                      (archive_error_string(reader.a) ? archive_error_string(reader.a) : "?"));
    }
    const std::string name = archive_entry_pathname(entry) ? archive_entry_pathname(entry) : "";
    // libarchive reports a hard link as a regular file with a link target: refuse those too.
    if (archive_entry_filetype(entry) != AE_IFREG || archive_entry_hardlink(entry) ||
        archive_entry_symlink(entry)) {
      report("entry '" + printableName(name) + "' is a link or not a plain file, ignored");
      continue;
    }
    if (unsafePath(name)) {
      report("entry '" + printableName(name) + "' is not a plain file name, ignored");
      continue;
    }
    const la_int64_t size = archive_entry_size_is_set(entry) ? archive_entry_size(entry) : -1;
    if (size > 0 && static_cast<uint64_t>(size) > shardBytes) {
      flush();
      throw Error(path, "shard is truncated or corrupt: entry '" + printableName(name) +
                            "' claims " + std::to_string(size) + " bytes, more than the shard's " +
                            std::to_string(shardBytes));
    }
    if (size < 0 || static_cast<uint64_t>(size) > options.maxEntryBytes) {
      report("entry '" + printableName(name) + "' has an invalid size (" + std::to_string(size) +
             " bytes, limit " + std::to_string(options.maxEntryBytes) + "), ignored");
      continue;
    }
    std::string key, member;
    if (!splitEntry(name, key, member)) {
      report("entry '" + printableName(name) + "' has no key, ignored");
      continue;
    }
    if (key != current.key) {
      flush();
      current.key = key;
    }
    std::vector<unsigned char> data(static_cast<size_t>(size));
    if (size > 0 && archive_read_data(reader.a, data.data(), data.size()) != size) {
      flush();
      throw Error(path, "shard is truncated or corrupt in entry '" + printableName(name) + "'");
    }
    if (member == "1.jpg")
      current.jpeg[0] = std::move(data);
    else if (member == "2.jpg")
      current.jpeg[1] = std::move(data);
    else if (member == "1.depth.exr")
      current.depthExr[0] = std::move(data);
    else if (member == "2.depth.exr")
      current.depthExr[1] = std::move(data);
    else if (member == "json") {
      current.record = nlohmann::json::parse(data.begin(), data.end(), nullptr, false);
      if (current.record.is_discarded()) current.record = nullptr;
    }
  }
  flush();
  return delivered;
}

std::vector<std::string> shardKeys(const std::string& path) {
  ArchiveReader reader(path);
  std::vector<std::string> keys;
  archive_entry* entry = nullptr;
  int r;
  while ((r = archive_read_next_header(reader.a, &entry)) == ARCHIVE_OK || r == ARCHIVE_WARN) {
    std::string key, member;
    const char* name = archive_entry_pathname(entry);
    if (name && splitEntry(name, key, member) && (keys.empty() || keys.back() != key))
      keys.push_back(key);
  }
  if (r != ARCHIVE_EOF) throw Error(path, "shard is truncated or corrupt");
  return keys;
}

}  // namespace paircast
