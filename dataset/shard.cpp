#include "dataset/shard.h"

#include <archive.h>
#include <archive_entry.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>

#include "dataset/habitat_frame.h"
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
  const int V = s.views();
  nlohmann::json j;
  j["paircast_shard_version"] = kShardVersion;
  j["scene"] = s.scene;
  j["index"] = s.index;
  j["seed"] = s.seed;
  j["views"] = V;
  j["cameras"] = nlohmann::json::array();
  for (const Camera& c : s.camera) j["cameras"].push_back(cameraToJson(c));
  j["orientations"] = nlohmann::json::array();  // habitat quaternions (w, x, y, z)
  for (int k = 0; k < V; ++k)
    j["orientations"].push_back(k < static_cast<int>(s.orientation.size())
                                    ? s.orientation[k]
                                    : habitatQuaternion(s.camera[k].R_cam2world));
  j["camera1"] = j["cameras"][0];
  if (V >= 2) {
    j["camera2"] = j["cameras"][1];
    j["covis"] = s.covis[1].covis;
    j["v_ij"] = s.covis[1].v_ij;
    j["v_ji"] = s.covis[1].v_ji;
  }
  // CroCo's: view 1's valid fraction, then each view's covis with view 1.
  std::vector<double> ratios{s.visibility[0][0]}, valid;
  for (int k = 1; k < V; ++k) ratios.push_back(s.covis[k].covis);
  for (int k = 0; k < V; ++k) valid.push_back(s.visibility[k][k]);
  j["covisibility_ratios"] = ratios;
  j["valid_fractions"] = valid;
  j["pairwise_visibility_ratios"] = s.visibility;
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
  if (record.contains("views")) {
    const auto& v = record.at("views");
    if (!v.is_number_integer() || v.get<int64_t>() < 1 || v.get<int64_t>() > kMaxViews)
      throw Error(source, "'views' is not an integer in [1, " + std::to_string(kMaxViews) + "]");
    r.views = v.get<int>();
  }
  const char* cameraKeys[2] = {"camera1", "camera2"};
  for (int k = 0; k < std::min(r.views, 2); ++k) {
    if (!record.contains(cameraKeys[k]))
      throw Error(source, std::string("record has no '") + cameraKeys[k] + "'");
    r.camera.push_back(cameraFromJson(record.at(cameraKeys[k]), source + " " + cameraKeys[k]));
  }
  if (record.contains("cameras")) {
    const auto& cams = record.at("cameras");
    if (!cams.is_array() || cams.size() != static_cast<size_t>(r.views))
      throw Error(source, "'cameras' is not a list of " + std::to_string(r.views) + " cameras");
    for (int k = 0; k < std::min(r.views, 2); ++k)
      if (cams[k] != record.at(cameraKeys[k]))
        throw Error(source, std::string("'cameras' disagrees with '") + cameraKeys[k] + "'");
    for (int k = 2; k < r.views; ++k)
      r.camera.push_back(cameraFromJson(cams[k], source + " cameras[" + std::to_string(k) + "]"));
  } else if (r.views > 2) {
    throw Error(source, "record of " + std::to_string(r.views) + " views has no 'cameras'");
  }
  if (r.views >= 2) {
    r.covis = ratioField(record, "covis", source);
    r.v_ij = ratioField(record, "v_ij", source);
    r.v_ji = ratioField(record, "v_ji", source);
  }
  return r;
}

EncodedPair encodePair(const PairSample& s, bool withDepth, int jpegQuality) {
  EncodedPair e;
  e.key = sampleKey(s.scene, s.index);
  for (int k = 0; k < s.views(); ++k) {
    e.jpeg.push_back(encodeImage(s.rgb[k], "jpg", jpegQuality));
    if (withDepth) {
      PAIRCAST_CHECK_MSG(!s.depth[k].data.empty(), "depth requested but not kept");
      e.depthExr.push_back(encodeExr(s.depth[k]));
    }
    if (!s.covisMask.empty()) e.covisPng.push_back(encodeImage(s.covisMask[k], "png", 0));
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
  for (size_t k = 0; k < p.jpeg.size(); ++k) {
    const std::string view = p.key + "." + std::to_string(k + 1);
    addFile(view + ".jpg", p.jpeg[k].data(), p.jpeg[k].size());
    if (k < p.depthExr.size())
      addFile(view + ".depth.exr", p.depthExr[k].data(), p.depthExr[k].size());
    if (k < p.covisPng.size())
      addFile(view + ".covis.png", p.covisPng[k].data(), p.covisPng[k].size());
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

// "<k>.jpg", "<k>.depth.exr" or "<k>.covis.png" with k in [1, kMaxViews]: stored in view k - 1.
// Other members are ignored.
void storeViewMember(ShardSample& s, const std::string& member, Bytes&& data) {
  const size_t dot = member.find('.');
  if (dot == 0 || dot == std::string::npos || dot > 2) return;
  int k = 0;
  for (size_t i = 0; i < dot; ++i) {
    if (!std::isdigit(static_cast<unsigned char>(member[i]))) return;
    k = 10 * k + (member[i] - '0');
  }
  const std::string kind = member.substr(dot + 1);
  std::vector<Bytes>* slot = kind == "jpg"         ? &s.jpeg
                             : kind == "depth.exr" ? &s.depthExr
                             : kind == "covis.png" ? &s.covisPng
                                                   : nullptr;
  if (!slot || k < 1 || k > kMaxViews || std::to_string(k).size() != dot) return;
  if (slot->size() < static_cast<size_t>(k)) slot->resize(k);
  (*slot)[k - 1] = std::move(data);
}

// Every view has its image, and depth and masks are there for all views or none.
bool wholeSample(ShardSample& s, int views) {
  auto whole = [&](std::vector<Bytes>& files, bool optional) {
    if (optional && files.empty()) return true;
    if (files.size() != static_cast<size_t>(views)) return false;
    return std::none_of(files.begin(), files.end(), [](const Bytes& b) { return b.empty(); });
  };
  return whole(s.jpeg, false) && whole(s.depthExr, true) && whole(s.covisPng, true);
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
    SampleRecord r;
    if (!s.record.is_null()) {
      try {
        r = parseSampleRecord(s.record, "sample '" + printableName(s.key) + "'");
      } catch (const Error& e) {
        report(std::string(e.what()) + ", skipped");
        return;
      }
    }
    if (s.record.is_null() || !wholeSample(s, r.views)) {
      report("sample '" + printableName(s.key) + "' is incomplete, skipped");
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
    if (member == "json") {
      current.record = nlohmann::json::parse(data.begin(), data.end(), nullptr, false);
      if (current.record.is_discarded()) current.record = nullptr;
    } else {
      storeViewMember(current, member, std::move(data));
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
