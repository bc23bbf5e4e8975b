#include "trainer/augment.h"

#include <algorithm>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "model/croco_net.h"
#include "util/error.h"
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

// The draws of jitterAndNormalize: the order of the three jitters and their factors.
struct Jitter {
  int order[3] = {0, 1, 2};
  double brightness = 1, contrast = 1, saturation = 1;
};

Jitter drawJitter(const AugmentOptions& o, Rng& rng) {
  Jitter j;
  for (int i = 2; i > 0; --i) std::swap(j.order[i], j.order[rng.below(i + 1)]);
  j.brightness = rng.uniform(o.jitterLow, o.jitterHigh);
  j.contrast = rng.uniform(o.jitterLow, o.jitterHigh);
  j.saturation = rng.uniform(o.jitterLow, o.jitterHigh);
  return j;
}

}  // namespace

torch::Tensor jitterAndNormalize(torch::Tensor x, const AugmentOptions& o, Rng& rng) {
  if (o.colorJitter) {
    const Jitter j = drawJitter(o, rng);
    x = colorJitter(x, j.brightness, j.contrast, j.saturation, j.order);
  }
  return imagenetNormalize(x.unsqueeze(0)).squeeze(0).contiguous();
}

namespace {

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

namespace {

// The float kernels below compute, element by element, what colorJitter's and
// imagenetNormalize's torch operations compute: each product, sum and clamp in float32, in the
// same order (so the file is built without floating-point contraction), and the grey plane's
// mean through torch's own reduction. The planes are [3][S S], channel by channel.

// toTensor of a crop, decoded as [3][S S]: x / 255.
void unitFloat(const uint8_t* chw, int64_t n, float* x) {
  for (int64_t i = 0; i < 3 * n; ++i) x[i] = static_cast<float>(chw[i]) / 255.0f;
}

// gray(): (0.299 r + 0.587 g) + 0.114 b.
void grayPlane(const float* x, int64_t n, float* g) {
  for (int64_t i = 0; i < n; ++i)
    g[i] = (x[i] * 0.299f + x[n + i] * 0.587f) + x[2 * n + i] * 0.114f;
}

// clamp(x, 0, 1) of torch (min(max(x, 0), 1)); maxps and minps give the same for any x that
// is not NaN, four at a time.
float clamp01(float v) {
  return std::min(std::max(v, 0.0f), 1.0f);
}

// p[i] = clamp(p[i] f + (plane ? plane[i] : value), 0, 1) for i < n.
void scaleAddClamp(float* p, int64_t n, float f, const float* plane, float value) {
  int64_t i = 0;
#if defined(__SSE2__)
  const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f), factor = _mm_set1_ps(f),
               constant = _mm_set1_ps(value);
  for (; i + 4 <= n; i += 4) {
    const __m128 add = plane ? _mm_loadu_ps(plane + i) : constant;
    const __m128 v = _mm_add_ps(_mm_mul_ps(_mm_loadu_ps(p + i), factor), add);
    _mm_storeu_ps(p + i, _mm_min_ps(one, _mm_max_ps(zero, v)));
  }
#endif
  for (; i < n; ++i) p[i] = clamp01(p[i] * f + (plane ? plane[i] : value));
}

void jitterAndNormalizeInto(AugmentScratch& s, const AugmentOptions& o, Rng& rng, float* out) {
  const int64_t n = static_cast<int64_t>(s.size) * s.size;
  float* x = s.planes.data();
  float* g = s.gray.data_ptr<float>();
  if (o.colorJitter) {
    const Jitter j = drawJitter(o, rng);
    for (int k : j.order) {
      if (k == 0) {
        scaleAddClamp(x, 3 * n, static_cast<float>(j.brightness), nullptr, 0.0f);
      } else if (k == 1) {
        grayPlane(x, n, g);
        const float mean = s.gray.mean().item<float>();
        const float shift = mean * static_cast<float>(1 - j.contrast);
        scaleAddClamp(x, 3 * n, static_cast<float>(j.contrast), nullptr, shift);
      } else {
        grayPlane(x, n, g);
        const float f = static_cast<float>(1 - j.saturation);
        for (int64_t i = 0; i < n; ++i) g[i] = g[i] * f;
        for (int c = 0; c < 3; ++c)
          scaleAddClamp(x + c * n, n, static_cast<float>(j.saturation), g, 0.0f);
      }
    }
  }
  for (int c = 0; c < 3; ++c)
    for (int64_t i = 0; i < n; ++i)
      out[c * n + i] = (x[c * n + i] - kImagenetMean[c]) / kImagenetStd[c];
}

}  // namespace

AugmentScratch::AugmentScratch(int s)
    : size(s), crop(s, s, 3), planes(size_t{3} * s * s), gray(torch::empty({s, s})) {}

namespace {

// randomCrop's draws and the crop decoded as [3][S S] uint8 into `chw`, when `e` is a JPEG at
// least S x S; false (and no draws) otherwise.
bool decodeCrop(const EncodedImage& e, int size, Rng& rng, uint8_t* chw) {
  if (!isJpeg(e)) return false;
  const JpegSize full = jpegSize(e.bytes.data(), e.bytes.size(), e.name);
  if (full.width < size || full.height < size) return false;
  CropBox box;
  box.height = box.width = size;
  box.top = static_cast<int>(rng.below(full.height - size + 1));
  box.left = static_cast<int>(rng.below(full.width - size + 1));
  decodeJpegCrop(e.bytes.data(), e.bytes.size(), e.name, box, PixelLayout::kUint8CHW, chw);
  return true;
}

}  // namespace

void augmentEncodedPairInto(const EncodedImage& a, const EncodedImage& b, const AugmentOptions& o,
                            Rng& rng, AugmentScratch& s, torch::Tensor out1, torch::Tensor out2) {
  PAIRCAST_CHECK(s.size == o.size);
  const EncodedImage* images[2] = {&a, &b};
  torch::Tensor* outs[2] = {&out1, &out2};
  for (int k = 0; k < 2; ++k) {
    const EncodedImage& e = *images[k];
    torch::Tensor& out = *outs[k];
    PAIRCAST_CHECK(out.is_contiguous() && out.scalar_type() == torch::kFloat32 &&
                   out.numel() == 3 * static_cast<int64_t>(o.size) * o.size);
    if (decodeCrop(e, o.size, rng, s.crop.data.data())) {
      unitFloat(s.crop.data.data(), static_cast<int64_t>(o.size) * o.size, s.planes.data());
      jitterAndNormalizeInto(s, o, rng, out.data_ptr<float>());
    } else {
      out.copy_(jitterAndNormalize(cropEncoded(e, o.size, rng), o, rng));
    }
  }
}

void cropEncodedPairInto(const EncodedImage& a, const EncodedImage& b, const AugmentOptions& o,
                         Rng& rng, AugmentScratch& s, torch::Tensor out1, torch::Tensor out2,
                         float* jitter1, float* jitter2) {
  const EncodedImage* images[2] = {&a, &b};
  torch::Tensor* outs[2] = {&out1, &out2};
  float* draws[2] = {jitter1, jitter2};
  for (int k = 0; k < 2; ++k) {
    const EncodedImage& e = *images[k];
    torch::Tensor& out = *outs[k];
    PAIRCAST_CHECK(out.is_contiguous() && out.scalar_type() == torch::kUInt8 &&
                   out.numel() == 3 * static_cast<int64_t>(o.size) * o.size);
    if (!decodeCrop(e, o.size, rng, out.data_ptr<uint8_t>()))
      out.copy_((cropEncoded(e, o.size, rng) * 255).round().clamp(0, 255));
    Jitter j;
    if (o.colorJitter) j = drawJitter(o, rng);
    draws[k][0] = static_cast<float>(100 * j.order[0] + 10 * j.order[1] + j.order[2]);
    draws[k][1] = static_cast<float>(j.brightness);
    draws[k][2] = static_cast<float>(j.contrast);
    draws[k][3] = static_cast<float>(j.saturation);
  }
}

torch::Tensor jitterAndNormalizeBatch(const torch::Tensor& crops, const torch::Tensor& jitter) {
  const auto column = [&](int k) { return jitter.select(1, k).view({-1, 1, 1, 1}); };
  const torch::Tensor packed = jitter.select(1, 0).round().to(torch::kLong);
  const torch::Tensor brightness = column(1), contrast = column(2), saturation = column(3);
  torch::Tensor x = crops.to(torch::kFloat32) / 255.0;
  auto gray = [](const torch::Tensor& t) {
    return (0.299 * t.select(1, 0) + 0.587 * t.select(1, 1) + 0.114 * t.select(1, 2)).unsqueeze(1);
  };
  for (int step = 0; step < 3; ++step) {  // the op each image takes at this step, chosen per image
    const int64_t divisor = step == 0 ? 100 : step == 1 ? 10 : 1;
    const torch::Tensor op = packed.div(divisor, "floor").remainder(10).view({-1, 1, 1, 1});
    const torch::Tensor g = gray(x);
    const torch::Tensor bright = (x * brightness).clamp(0, 1);
    const torch::Tensor contr =
        (contrast * x + (1 - contrast) * g.mean({1, 2, 3}, true)).clamp(0, 1);
    const torch::Tensor sat = (saturation * x + (1 - saturation) * g).clamp(0, 1);
    x = torch::where(op == 0, bright, torch::where(op == 1, contr, sat));
  }
  return imagenetNormalize(x);
}

}  // namespace paircast
