// Plain images with interleaved channels, row-major: data[(y * width + x) * channels + c].
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace paircast {

template <typename T>
struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<T> data;  // [H, W, C]

  Image() = default;
  Image(int w, int h, int c, T fill = T())
      : width(w), height(h), channels(c), data(static_cast<size_t>(w) * h * c, fill) {}
  void resize(int w, int h, int c) {
    width = w;
    height = h;
    channels = c;
    data.resize(static_cast<size_t>(w) * h * c);
  }
  T* pixel(int x, int y) { return data.data() + (static_cast<size_t>(y) * width + x) * channels; }
  const T* pixel(int x, int y) const {
    return data.data() + (static_cast<size_t>(y) * width + x) * channels;
  }
  size_t size() const { return data.size(); }
};

using Image8 = Image<uint8_t>;
using ImageF = Image<float>;
using ImageI = Image<int32_t>;

}  // namespace paircast
