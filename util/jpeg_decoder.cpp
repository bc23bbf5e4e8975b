#include "util/jpeg_decoder.h"

#include <algorithm>
#include <cstdlib>
#include <cstring>

#include "util/error.h"
#include "util/jpeg_errors.h"

namespace paircast {
namespace {

// The most pixels a JPEG may claim: a few bytes of header can claim any size, and shards come
// from downloads.
constexpr uint64_t kMaxPixels = uint64_t(1) << 28;

// (x / 255 - mean) / std in float32, as torchvision's ToTensor and Normalize compute it.
struct NormalizeTable {
  float value[3][256];
  NormalizeTable() {
    for (int c = 0; c < 3; ++c)
      for (int v = 0; v < 256; ++v)
        value[c][v] = (static_cast<float>(v) / 255.0f - kImagenetMean[c]) / kImagenetStd[c];
  }
};

// One decoded row of the crop (`src`: its W RGB pixels) into row y of `out`.
void storeRow(const uint8_t* src, int y, const CropBox& box, PixelLayout layout, void* out) {
  static const NormalizeTable table;
  const size_t plane = static_cast<size_t>(box.height) * box.width;
  const size_t row = static_cast<size_t>(y) * box.width;
  switch (layout) {
    case PixelLayout::kUint8HWC:
      std::memcpy(static_cast<uint8_t*>(out) + 3 * row, src, 3 * static_cast<size_t>(box.width));
      return;
    case PixelLayout::kUint8CHW: {
      auto* dst = static_cast<uint8_t*>(out) + row;
      for (int x = 0; x < box.width; ++x)
        for (int c = 0; c < 3; ++c) dst[c * plane + x] = src[3 * x + c];
      return;
    }
    case PixelLayout::kNormalizedFloatCHW: {
      auto* dst = static_cast<float*>(out) + row;
      for (int x = 0; x < box.width; ++x)
        for (int c = 0; c < 3; ++c) dst[c * plane + x] = table.value[c][src[3 * x + c]];
      return;
    }
  }
}

// Decodes `box` into `out`. Returns "" on success, else the reason. Everything that must be
// freed on an error is malloc'd and held in volatile pointers, since longjmp skips destructors.
std::string decode(const uint8_t* data, size_t size, const CropBox* box, PixelLayout layout,
                   void* out, JpegSize* headerOnly) {
  jpeg_decompress_struct cinfo;
  jpeg::ErrorManager err;
  cinfo.err = jpeg::install(err, jpeg::onMessageStrict);
  uint8_t* volatile rowBuffer = nullptr;
  if (setjmp(err.jump)) {
    std::free(rowBuffer);
    jpeg_destroy_decompress(&cinfo);
    return err.message;
  }
  jpeg_create_decompress(&cinfo);
  jpeg_mem_src(&cinfo, data, static_cast<unsigned long>(size));
  jpeg_read_header(&cinfo, TRUE);
  const int W = static_cast<int>(cinfo.image_width), H = static_cast<int>(cinfo.image_height);
  const uint64_t pixels = static_cast<uint64_t>(W) * static_cast<uint64_t>(H);
  if (pixels == 0 || pixels > kMaxPixels) {
    std::snprintf(err.message, sizeof err.message, "image is too large or empty (%dx%d)", W, H);
    std::longjmp(err.jump, 1);
  }
  if (headerOnly) {
    *headerOnly = {W, H};
    jpeg_destroy_decompress(&cinfo);
    return {};
  }
  if (box->top < 0 || box->left < 0 || box->height < 1 || box->width < 1 ||
      box->top + box->height > H || box->left + box->width > W) {
    std::snprintf(err.message, sizeof err.message,
                  "crop %dx%d at (%d, %d) is not inside the %dx%d image", box->width, box->height,
                  box->left, box->top, W, H);
    std::longjmp(err.jump, 1);
  }
  cinfo.out_color_space = JCS_RGB;
  cinfo.dct_method = JDCT_ISLOW;
  jpeg_start_decompress(&cinfo);
  // One iMCU column of margin on each side, so that fancy upsampling at the crop's edges sees
  // the same neighbours as in a full decode.
  const int margin = 8 * cinfo.max_h_samp_factor;
  JDIMENSION x0 = static_cast<JDIMENSION>(std::max(0, box->left - margin));
  JDIMENSION columns = static_cast<JDIMENSION>(std::min(W, box->left + box->width + margin)) - x0;
  if (x0 > 0 || columns < static_cast<JDIMENSION>(W)) jpeg_crop_scanline(&cinfo, &x0, &columns);
  rowBuffer = static_cast<uint8_t*>(std::malloc(3 * static_cast<size_t>(cinfo.output_width)));
  if (!rowBuffer) {
    std::snprintf(err.message, sizeof err.message, "out of memory");
    std::longjmp(err.jump, 1);
  }
  if (box->top > 0) jpeg_skip_scanlines(&cinfo, static_cast<JDIMENSION>(box->top));
  const size_t skip = 3 * static_cast<size_t>(box->left - static_cast<int>(x0));
  for (int y = 0; y < box->height; ++y) {
    JSAMPROW row = rowBuffer;
    if (jpeg_read_scanlines(&cinfo, &row, 1) != 1) {
      std::snprintf(err.message, sizeof err.message, "image data end early");
      std::longjmp(err.jump, 1);
    }
    storeRow(rowBuffer + skip, y, *box, layout, out);
  }
  std::free(rowBuffer);
  rowBuffer = nullptr;
  jpeg_abort_decompress(&cinfo);  // the rows below the crop are never decoded
  jpeg_destroy_decompress(&cinfo);
  return {};
}

}  // namespace

JpegSize jpegSize(const uint8_t* data, size_t size, const std::string& name) {
  JpegSize s;
  const std::string why = decode(data, size, nullptr, PixelLayout::kUint8HWC, nullptr, &s);
  if (!why.empty()) throw Error(name, "cannot decode JPEG: " + why);
  return s;
}

void decodeJpegCrop(const uint8_t* data, size_t size, const std::string& name, const CropBox& box,
                    PixelLayout layout, void* out) {
  const std::string why = decode(data, size, &box, layout, out, nullptr);
  if (!why.empty()) throw Error(name, "cannot decode JPEG: " + why);
}

}  // namespace paircast
