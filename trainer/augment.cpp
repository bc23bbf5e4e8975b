#include "trainer/augment.h"

#include "model/croco_net.h"
#include "util/jpeg_decoder.h"

namespace paircast {
namespace {

torch::Tensor toTensor(const Image8& img) {  // [3, H, W] in [0, 1]
  return torch::from_blob(const_cast<uint8_t*>(img.data.data()), {img.height, img.width, 3},
                          torch::kUInt8)
             .permute({2, 0, 1})
             .to(torch::kFloat32) /
         255.0;
}

torch::Tensor gray(const torch::Tensor& x) {  // [3, H, W] -> [1, H, W], ITU-R 601
  return (0.299 * x[0] + 0.587 * x[1] + 0.114 * x[2]).unsqueeze(0);
}

torch::Tensor randomCrop(const torch::Tensor& x, int size, Rng& rng) {
  torch::Tensor t = x;
  if (t.size(1) < size || t.size(2) < size) {
    const double s = static_cast<double>(size) / std::min(t.size(1), t.size(2));
    t = torch::nn::functional::interpolate(
            t.unsqueeze(0),
            torch::nn::functional::InterpolateFuncOptions()
                .size(std::vector<int64_t>{std::max<int64_t>(size, std::lround(t.size(1) * s)),
                                           std::max<int64_t>(size, std::lround(t.size(2) * s))})
                .mode(torch::kBilinear)
                .align_corners(false))
            .squeeze(0);
  }
  const int64_t y0 = rng.below(t.size(1) - size + 1), x0 = rng.below(t.size(2) - size + 1);
  return t.narrow(1, y0, size).narrow(2, x0, size);
}

}  // namespace

torch::Tensor colorJitter(const torch::Tensor& x0, double brightness, double contrast,
                          double saturation, const int order[3]) {
  torch::Tensor x = x0;
  for (int k = 0; k < 3; ++k) {
    if (order[k] == 0)
      x = (x * brightness).clamp(0, 1);
    else if (order[k] == 1)
      x = (contrast * x + (1 - contrast) * gray(x).mean()).clamp(0, 1);
    else
      x = (saturation * x + (1 - saturation) * gray(x)).clamp(0, 1);
  }
  return x;
}

namespace {

// The colour jitter (when on) and the normalisation of one cropped image, [3, S, S] in [0, 1].
torch::Tensor jitterAndNormalize(torch::Tensor x, const AugmentOptions& o, Rng& rng) {
  if (o.colorJitter) {
    int order[3] = {0, 1, 2};
    for (int i = 2; i > 0; --i) std::swap(order[i], order[rng.below(i + 1)]);  // random order
    const double br = rng.uniform(o.jitterLow, o.jitterHigh),
                 ct = rng.uniform(o.jitterLow, o.jitterHigh),
                 st = rng.uniform(o.jitterLow, o.jitterHigh);
    x = colorJitter(x, br, ct, st, order);
  }
  return imagenetNormalize(x.unsqueeze(0)).squeeze(0).contiguous();
}

bool isJpeg(const EncodedImage& e) {
  return e.bytes.size() >= 3 && e.bytes[0] == 0xff && e.bytes[1] == 0xd8 && e.bytes[2] == 0xff;
}

// randomCrop's draws, with only the crop decoded when the image is a JPEG at least S x S.
torch::Tensor cropEncoded(const EncodedImage& e, int size, Rng& rng) {
  if (isJpeg(e)) {
    const JpegSize full = jpegSize(e.bytes.data(), e.bytes.size(), e.name);
    if (full.width >= size && full.height >= size) {
      CropBox box;
      box.height = box.width = size;
      box.top = static_cast<int>(rng.below(full.height - size + 1));
      box.left = static_cast<int>(rng.below(full.width - size + 1));
      Image8 crop(size, size, 3);
      decodeJpegCrop(e.bytes.data(), e.bytes.size(), e.name, box, PixelLayout::kUint8HWC,
                     crop.data.data());
      return toTensor(crop);
    }
  }
  return randomCrop(toTensor(decodeImage8(e.bytes.data(), e.bytes.size(), e.name)), size, rng);
}

}  // namespace

std::pair<torch::Tensor, torch::Tensor> augmentPair(const Image8& a, const Image8& b,
                                                    const AugmentOptions& o, Rng& rng) {
  torch::Tensor out[2];
  const Image8* imgs[2] = {&a, &b};
  for (int k = 0; k < 2; ++k)
    out[k] = jitterAndNormalize(randomCrop(toTensor(*imgs[k]), o.size, rng), o, rng);
  return {out[0], out[1]};
}

std::pair<torch::Tensor, torch::Tensor> augmentEncodedPair(const EncodedImage& a,
                                                           const EncodedImage& b,
                                                           const AugmentOptions& o, Rng& rng) {
  torch::Tensor x = jitterAndNormalize(cropEncoded(a, o.size, rng), o, rng);
  torch::Tensor y = jitterAndNormalize(cropEncoded(b, o.size, rng), o, rng);
  return {x, y};
}

}  // namespace paircast
