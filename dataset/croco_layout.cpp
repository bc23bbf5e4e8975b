#include "dataset/croco_layout.h"

#include <cstdio>

#include "util/atomic_file.h"

namespace paircast {
namespace {

std::string_view bytesView(const Bytes& v) {
  return std::string_view(reinterpret_cast<const char*>(v.data()), v.size());
}

}  // namespace

std::string crocoIndex(uint64_t index) {
  char b[32];
  std::snprintf(b, sizeof b, "%08llu", static_cast<unsigned long long>(index));
  return b;
}

void writeCrocoSample(const std::string& stem, const EncodedPair& enc,
                      const std::vector<Camera>& cameras) {
  const int views = static_cast<int>(enc.jpeg.size());
  for (int k = views - 1; k >= 0; --k) {
    const std::string view = stem + "_" + std::to_string(k + 1);
    if (!enc.depthExr.empty()) {
      writeFileAtomic(view + "_depth.exr", bytesView(enc.depthExr[k]), Durability::NoSync);
      nlohmann::json cam = cameraToJson(cameras.at(k));
      cam.erase("width");
      cam.erase("height");
      writeFileAtomic(view + "_camera_params.json", cam.dump() + "\n", Durability::NoSync);
    }
    if (!enc.covisPng.empty())
      writeFileAtomic(view + "_covis.png", bytesView(enc.covisPng[k]), Durability::NoSync);
    if (!enc.flowFlo.empty())
      writeFileAtomic(view + "_flow.flo", bytesView(enc.flowFlo[k]), Durability::NoSync);
  }
  for (int k = 0; k < views; ++k)
    writeFileAtomic(stem + "_" + std::to_string(k + 1) + ".jpeg", bytesView(enc.jpeg[k]),
                    Durability::NoSync);
}

std::string crocoPairLines(const std::string& scene, const std::string& index, int views) {
  std::string lines;
  const std::string first = scene + "/" + index + "_1.jpeg ";
  for (int k = 2; k <= views; ++k)
    lines += first + scene + "/" + index + "_" + std::to_string(k) + ".jpeg\n";
  return lines;
}

}  // namespace paircast
