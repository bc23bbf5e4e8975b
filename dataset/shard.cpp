#include "dataset/shard.h"

#include <archive.h>
#include <archive_entry.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "covis/flow.h"
#include "dataset/habitat_frame.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/flo_io.h"
#include "util/image_io.h"

namespace paircast {
namespace fs = std::filesystem;

SampleRecord sampleRecordOf(const PairSample& s) {
  const int V = s.views();
  SampleRecord r;
  r.scene = s.scene;
  r.index = s.index;
  r.seed = s.seed;
  r.views = V;
  r.camera = s.camera;
  for (int k = 0; k < V; ++k)
    r.rotation.push_back(k < static_cast<int>(s.orientation.size())
                             ? s.orientation[k]
                             : habitatQuaternion(s.camera[k].R_cam2world));
  if (V >= 2) {
    r.covis = s.covis[1].covis;
    r.v_ij = s.covis[1].v_ij;
    r.v_ji = s.covis[1].v_ji;
  }
  r.covisibilityRatios = {s.visibility[0][0]};
  for (int k = 1; k < V; ++k) r.covisibilityRatios.push_back(s.covis[k].covis);
  for (int k = 0; k < V; ++k) r.validFractions.push_back(s.visibility[k][k]);
  r.pairwiseVisibility = s.visibility;
  r.candidates = s.candidateCovis.size();
  return r;
}

nlohmann::json sampleRecord(const PairSample& s) {
  return recordToJson(sampleRecordOf(s));
}

std::vector<ImageF> viewFlows(const PairSample& s) {
  std::vector<ImageF> flows;
  for (int k = 0; k < s.views(); ++k) {
    PAIRCAST_CHECK_MSG(!s.depth[k].data.empty(), "flow requested but depth not kept");
    flows.push_back(opticalFlow(s.camera[k], s.depth[k], s.camera[flowTarget(k)]));
  }
  return flows;
}

EncodedPair encodePair(const PairSample& s, bool withDepth, int jpegQuality, bool withFlow) {
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
  if (withFlow)
    for (const ImageF& flow : viewFlows(s)) e.flowFlo.push_back(encodeFlo(flow));
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
    const int view = static_cast<int>(k) + 1;
    addFile(memberName(p.key, MemberKind::kImage, view), p.jpeg[k].data(), p.jpeg[k].size());
    if (k < p.depthExr.size())
      addFile(memberName(p.key, MemberKind::kDepth, view), p.depthExr[k].data(),
              p.depthExr[k].size());
    if (k < p.covisPng.size())
      addFile(memberName(p.key, MemberKind::kCovisMask, view), p.covisPng[k].data(),
              p.covisPng[k].size());
    if (k < p.flowFlo.size())
      addFile(memberName(p.key, MemberKind::kFlow, view), p.flowFlo[k].data(), p.flowFlo[k].size());
  }
  const std::string json = p.record.dump();
  addFile(memberName(p.key, MemberKind::kRecord), json.data(), json.size());
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

size_t readShard(const std::string& path, const std::function<void(ShardSample&&)>& onSample,
                 const std::function<void(const std::string&)>& onError,
                 const ShardReadOptions& options) {
  const ShardIndex index = ShardIndex::open(path, onError, options);
  auto readAll = [&](const std::vector<Extent>& list) {
    std::vector<Bytes> out;
    for (const Extent& e : list) out.push_back(index.read(e));
    return out;
  };
  for (const IndexedSample& s : index.samples()) {
    ShardSample out;
    out.key = s.key;
    out.jpeg = readAll(s.image);
    out.depthExr = readAll(s.depth);
    out.covisPng = readAll(s.covisMask);
    out.flowFlo = readAll(s.flow);
    out.record = s.json;
    onSample(std::move(out));
  }
  if (index.damaged()) throw Error(path, index.damage());
  return index.size();
}

}  // namespace paircast
