#include "shard/shard_format.h"

#include <algorithm>
#include <cctype>
#include <cstdio>

#include "util/error.h"

namespace paircast {

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

// ---- Member names ------------------------------------------------------------------------------

namespace {

struct KindSuffix {
  MemberKind kind;
  const char* suffix;
};
constexpr KindSuffix kViewSuffixes[] = {{MemberKind::kImage, "jpg"},
                                        {MemberKind::kDepth, "depth.exr"},
                                        {MemberKind::kCovisMask, "covis.png"},
                                        {MemberKind::kFlow, "flow.flo"}};

}  // namespace

std::string memberName(const std::string& key, MemberKind kind, int view) {
  if (kind == MemberKind::kRecord) return key + ".json";
  for (const KindSuffix& k : kViewSuffixes)
    if (k.kind == kind) return key + "." + std::to_string(view) + "." + k.suffix;
  PAIRCAST_CHECK_MSG(false, "unknown member kind");
  return {};
}

std::optional<MemberName> parseMemberName(const std::string& name) {
  const size_t dot = name.find('.');
  if (dot == std::string::npos || dot == 0) return std::nullopt;
  MemberName m;
  m.key = name.substr(0, dot);
  const std::string rest = name.substr(dot + 1);
  if (rest == "json") return m;
  const size_t dot2 = rest.find('.');
  const size_t digits = std::to_string(kMaxViews).size();
  if (dot2 == 0 || dot2 == std::string::npos || dot2 > digits || rest[0] == '0')
    return std::nullopt;
  for (size_t i = 0; i < dot2; ++i) {
    if (!std::isdigit(static_cast<unsigned char>(rest[i]))) return std::nullopt;
    m.view = 10 * m.view + (rest[i] - '0');
  }
  if (m.view < 1 || m.view > kMaxViews) return std::nullopt;
  const std::string suffix = rest.substr(dot2 + 1);
  for (const KindSuffix& k : kViewSuffixes) {
    if (suffix == k.suffix) {
      m.kind = k.kind;
      return m;
    }
  }
  return std::nullopt;
}

// ---- The record --------------------------------------------------------------------------------

nlohmann::json recordToJson(const SampleRecord& r, const nlohmann::json& extra) {
  nlohmann::json j = extra;
  j["paircast_shard_version"] = kShardVersion;
  j["scene"] = r.scene;
  j["index"] = r.index;
  if (r.seed) j["seed"] = *r.seed;
  j["views"] = r.views;
  j["cameras"] = nlohmann::json::array();
  for (const Camera& c : r.camera) j["cameras"].push_back(cameraToJson(c));
  if (!r.rotation.empty()) j["orientations"] = r.rotation;
  j["camera1"] = j["cameras"][0];
  if (r.views >= 2) {
    j["camera2"] = j["cameras"][1];
    j["covis"] = r.covis;
    j["v_ij"] = r.v_ij;
    j["v_ji"] = r.v_ji;
  }
  if (!r.covisibilityRatios.empty()) j["covisibility_ratios"] = r.covisibilityRatios;
  if (!r.validFractions.empty()) j["valid_fractions"] = r.validFractions;
  if (!r.pairwiseVisibility.empty()) j["pairwise_visibility_ratios"] = r.pairwiseVisibility;
  if (r.candidates) j["candidates"] = *r.candidates;
  return j;
}

void checkShardVersion(const nlohmann::json& record, const std::string& shard) {
  const auto version = record.is_object() ? record.find("paircast_shard_version") : record.end();
  if (record.is_object() && version != record.end() && version->is_number_integer() &&
      version->get<int64_t>() == kShardVersion)
    return;
  const std::string found =
      !record.is_object() || version == record.end() ? std::string("none") : version->dump();
  throw Error(shard, "has an unsupported version (paircast_shard_version " + found +
                         ", this build reads version " + std::to_string(kShardVersion) +
                         "; regenerate the shard with generate_pairs)");
}

namespace {

double ratioField(const nlohmann::json& record, const char* key, const std::string& source) {
  if (!record.contains(key) || !record.at(key).is_number())
    throw Error(source, std::string("record has no number '") + key + "'");
  const double v = record.at(key).get<double>();
  if (!(v >= 0 && v <= 1)) throw Error(source, std::string("'") + key + "' is not in [0, 1]");
  return v;
}

// A list of `n` ratios in [0, 1] under `key`, or empty when the record has none.
std::vector<double> ratioList(const nlohmann::json& j, size_t n, const std::string& what,
                              const std::string& source) {
  if (!j.is_array() || j.size() != n)
    throw Error(source, "'" + what + "' is not a list of " + std::to_string(n) + " ratios");
  std::vector<double> out;
  for (const auto& v : j) {
    if (!v.is_number() || !(v.get<double>() >= 0 && v.get<double>() <= 1))
      throw Error(source, "'" + what + "' holds a value that is not a ratio in [0, 1]");
    out.push_back(v.get<double>());
  }
  return out;
}

std::optional<uint64_t> optionalCount(const nlohmann::json& record, const char* key,
                                      const std::string& source) {
  if (!record.contains(key)) return std::nullopt;
  if (!record.at(key).is_number_unsigned())
    throw Error(source, std::string("'") + key + "' is not a non-negative integer");
  return record.at(key).get<uint64_t>();
}

void parseCameras(const nlohmann::json& record, const std::string& source, SampleRecord& r) {
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
}

void parseRotations(const nlohmann::json& record, const std::string& source, SampleRecord& r) {
  if (!record.contains("orientations")) return;
  const auto& list = record.at("orientations");
  if (!list.is_array() || list.size() != static_cast<size_t>(r.views))
    throw Error(source,
                "'orientations' is not a list of " + std::to_string(r.views) + " quaternions");
  for (const auto& q : list) {
    if (!q.is_array() || q.size() != 4 ||
        !std::all_of(q.begin(), q.end(), [](const nlohmann::json& v) { return v.is_number(); }))
      throw Error(source, "'orientations' holds a value that is not 4 numbers (w, x, y, z)");
    r.rotation.push_back(
        {q[0].get<double>(), q[1].get<double>(), q[2].get<double>(), q[3].get<double>()});
  }
}

void parseRatios(const nlohmann::json& record, const std::string& source, SampleRecord& r) {
  const size_t V = static_cast<size_t>(r.views);
  if (r.views >= 2) {
    r.covis = ratioField(record, "covis", source);
    r.v_ij = ratioField(record, "v_ij", source);
    r.v_ji = ratioField(record, "v_ji", source);
  }
  if (record.contains("covisibility_ratios"))
    r.covisibilityRatios =
        ratioList(record.at("covisibility_ratios"), V, "covisibility_ratios", source);
  if (record.contains("valid_fractions"))
    r.validFractions = ratioList(record.at("valid_fractions"), V, "valid_fractions", source);
  if (record.contains("pairwise_visibility_ratios")) {
    const auto& rows = record.at("pairwise_visibility_ratios");
    if (!rows.is_array() || rows.size() != V)
      throw Error(source, "'pairwise_visibility_ratios' is not " + std::to_string(V) + " x " +
                              std::to_string(V));
    for (const auto& row : rows)
      r.pairwiseVisibility.push_back(ratioList(row, V, "pairwise_visibility_ratios", source));
  }
}

}  // namespace

SampleRecord parseSampleRecord(const nlohmann::json& record, const std::string& source) {
  if (!record.is_object()) throw Error(source, "record is not a JSON object");
  checkShardVersion(record, source);
  SampleRecord r;
  if (!record.contains("scene") || !record.at("scene").is_string())
    throw Error(source, "record has no string 'scene'");
  r.scene = record.at("scene").get<std::string>();
  if (!record.contains("index") || !record.at("index").is_number_unsigned())
    throw Error(source, "record has no non-negative integer 'index'");
  r.index = record.at("index").get<uint64_t>();
  r.seed = optionalCount(record, "seed", source);
  if (record.contains("views")) {
    const auto& v = record.at("views");
    if (!v.is_number_integer() || v.get<int64_t>() < 1 || v.get<int64_t>() > kMaxViews)
      throw Error(source, "'views' is not an integer in [1, " + std::to_string(kMaxViews) + "]");
    r.views = v.get<int>();
  }
  parseCameras(record, source, r);
  parseRotations(record, source, r);
  parseRatios(record, source, r);
  r.candidates = optionalCount(record, "candidates", source);
  return r;
}

}  // namespace paircast
