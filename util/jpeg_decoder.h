// JPEG decoding through libjpeg-turbo straight into a crop, in the layout its consumer takes:
// only the crop's rows are decoded (the rows above it are skipped with jpeg_skip_scanlines, the
// rows below it never read) and only the iMCU columns that hold it (jpeg_crop_scanline). Pixels
// are those of a full decode (the same libjpeg-turbo, JDCT_ISLOW, fancy upsampling, as PIL's), so a
// crop equals the same window of the whole image.
//
// Legend: H, W pixels of the crop.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace paircast {

struct JpegSize {
  int width = 0, height = 0;
};

// A window of the image, in pixels.
struct CropBox {
  int top = 0, left = 0, height = 0, width = 0;
};

enum class PixelLayout {
  kUint8HWC,           // [H, W, 3] uint8 (an Image8's layout)
  kUint8CHW,           // [3, H, W] uint8, for consumers that normalise on the GPU
  kNormalizedFloatCHW  // [3, H, W] float32, (x / 255 - mean) / std with ImageNet's mean and std
};

// ImageNet's mean and std, as CroCo's transforms normalise with.
constexpr float kImagenetMean[3] = {0.485f, 0.456f, 0.406f};
constexpr float kImagenetStd[3] = {0.229f, 0.224f, 0.225f};

// The size in the JPEG's header. Throws paircast::Error naming `name` when it is no JPEG.
JpegSize jpegSize(const uint8_t* data, size_t size, const std::string& name);

// Decodes `box` of the RGB JPEG into `out`: H W 3 elements of uint8 or float32 as `layout`
// says. Throws paircast::Error naming `name` when the data are no JPEG, the box is not inside the
// image, or the image is larger than 2^28 pixels (checked before anything is allocated).
void decodeJpegCrop(const uint8_t* data, size_t size, const std::string& name, const CropBox& box,
                    PixelLayout layout, void* out);

}  // namespace paircast
