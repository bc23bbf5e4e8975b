#include "util/flo_io.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>

#include "util/error.h"

namespace paircast {
namespace {

// Values are stored in the machine's order, which must be little-endian as the format's.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, ".flo files are little-endian");

constexpr size_t kHeader = 12;
constexpr int32_t kMaxSide = 1 << 16;

}  // namespace

std::vector<unsigned char> encodeFlo(const ImageF& flow) {
  PAIRCAST_CHECK_MSG(flow.channels == 2 && flow.size() == size_t(flow.width) * flow.height * 2,
                     "a flow image is [H, W, 2]");
  std::vector<unsigned char> out(kHeader + flow.size() * sizeof(float));
  const int32_t wh[2] = {flow.width, flow.height};
  std::memcpy(out.data(), &kFloMagic, 4);
  std::memcpy(out.data() + 4, wh, 8);
  std::memcpy(out.data() + kHeader, flow.data.data(), flow.size() * sizeof(float));
  return out;
}

ImageF decodeFlo(const void* data, size_t size, const std::string& name) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  if (size < kHeader) throw Error(name, "not a .flo file: " + std::to_string(size) + " bytes");
  float magic;
  int32_t wh[2];
  std::memcpy(&magic, bytes, 4);
  std::memcpy(wh, bytes + 4, 8);
  if (magic != kFloMagic) throw Error(name, "not a .flo file: wrong magic number");
  if (wh[0] < 1 || wh[1] < 1 || wh[0] > kMaxSide || wh[1] > kMaxSide)
    throw Error(name, "bad .flo size " + std::to_string(wh[0]) + "x" + std::to_string(wh[1]));
  // The byte count is checked against the header before anything is allocated: a 12-byte file
  // that claims 65,536 x 65,536 must not ask for 32 GiB.
  const size_t values = size_t(wh[0]) * size_t(wh[1]) * 2;
  const size_t expected = kHeader + values * sizeof(float);
  if (size != expected)
    throw Error(name, "truncated or padded .flo: " + std::to_string(size) + " bytes, expected " +
                          std::to_string(expected) + " for " + std::to_string(wh[0]) + "x" +
                          std::to_string(wh[1]));
  ImageF flow(wh[0], wh[1], 2);
  std::memcpy(flow.data.data(), bytes + kHeader, flow.size() * sizeof(float));
  return flow;
}

ImageF readFlo(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path, "cannot open");
  const std::vector<char> bytes{std::istreambuf_iterator<char>(in), {}};
  return decodeFlo(bytes.data(), bytes.size(), path);
}

}  // namespace paircast
