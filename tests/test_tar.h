// Hand-made tar shards for tests: ustar archives written header by header, so that a test can
// write what no tar tool would (links, sizes beyond the file, views missing from a sample).
#pragma once

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "shard/shard_format.h"
#include "util/image.h"
#include "util/image_io.h"

namespace paircast::testing {

struct TarMember {
  TarMember(std::string n, std::string d, char t = '0', std::string size = "")
      : name(std::move(n)), data(std::move(d)), type(t), sizeField(std::move(size)) {}
  std::string name, data;
  char type;              // ustar type flag: '0' file, '1' hard link, '2' symlink, '5' folder
  std::string sizeField;  // written instead of the real size when set
};

// The bytes of a ustar archive of `members`, in order.
inline std::string ustar(const std::vector<TarMember>& members) {
  std::string out;
  for (const TarMember& m : members) {
    char h[512] = {};
    std::strncpy(h, m.name.c_str(), 100);
    std::snprintf(h + 100, 8, "%07o", 0644);
    std::snprintf(h + 108, 8, "%07o", 0);
    std::snprintf(h + 116, 8, "%07o", 0);
    if (m.sizeField.empty())
      std::snprintf(h + 124, 12, "%011o", static_cast<unsigned>(m.data.size()));
    else
      std::memcpy(h + 124, m.sizeField.data(), std::min<size_t>(12, m.sizeField.size()));
    std::snprintf(h + 136, 12, "%011o", 0);
    h[156] = m.type;
    std::memcpy(h + 257,
                "ustar\0"
                "00",
                8);
    std::memset(h + 148, ' ', 8);
    unsigned sum = 0;
    for (unsigned char c : std::string(h, 512)) sum += c;
    std::snprintf(h + 148, 8, "%06o", sum);
    out.append(h, 512);
    out += m.data;
    out.append((512 - m.data.size() % 512) % 512, '\0');
  }
  return out + std::string(1024, '\0');
}

// A JPEG of `size` x `size` pixels, all of grey level `level` (a gradient when level < 0).
inline std::string jpegBytes(int level = -1, int size = 8) {
  Image8 img(size, size, 3);
  for (size_t i = 0; i < img.data.size(); ++i)
    img.data[i] = static_cast<uint8_t>(level >= 0 ? level : i * 7);
  const auto bytes = encodeImage(img, "jpg", 90);
  return std::string(bytes.begin(), bytes.end());
}

// The record member "<key>.json" of a sample of `views` views of width x height, as the shard
// format requires it (shard/shard_format.h): the key's scene and index, one camera a view.
inline TarMember recordMember(const std::string& key, int views, int width = 8, int height = 8) {
  SampleRecord r;
  const size_t dash = key.rfind('-');
  r.scene = key.substr(0, dash);
  r.index = dash == std::string::npos ? 0 : std::strtoull(key.c_str() + dash + 1, nullptr, 10);
  r.views = views;
  for (int k = 0; k < views; ++k) {
    r.camera.push_back(Camera::fromHfov(width, height, 60));
    r.camera.back().t_cam2world.x() = 0.1 * k;
  }
  if (views >= 2) r.covis = r.v_ij = r.v_ji = 0.5;
  return {key + ".json", recordToJson(r).dump()};
}

}  // namespace paircast::testing
