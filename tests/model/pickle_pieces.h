// Pickle pieces for hand-written pickles in the model tests (protocol 2): strings, 8-byte ints and
// a float32 tensor rebuilt from a storage record, as torch.save writes them.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace paircast::testing {

inline std::string str(const std::string& s) {  // BINUNICODE
  const uint32_t n = static_cast<uint32_t>(s.size());
  return "X" + std::string(reinterpret_cast<const char*>(&n), 4) + s;
}
inline std::string i64(int64_t v) {  // LONG1, 8 bytes
  return std::string("\x8a\x08", 2) + std::string(reinterpret_cast<const char*>(&v), 8);
}
// _rebuild_tensor_v2(storage(key, numel), offset, size, stride, False, {}) of float32.
inline std::string tensor(const std::string& key, int64_t numel, int64_t offset,
                          const std::vector<int64_t>& size, const std::vector<int64_t>& stride) {
  std::string p = "ctorch._utils\n_rebuild_tensor_v2\n(";
  p += "(" + str("storage") + "ctorch\nFloatStorage\n" + str(key) + str("cpu") + i64(numel) + "tQ";
  p += i64(offset) + "(";
  for (int64_t s : size) p += i64(s);
  p += "t(";
  for (int64_t s : stride) p += i64(s);
  p += "t\x89}tR";
  return p;
}

}  // namespace paircast::testing
