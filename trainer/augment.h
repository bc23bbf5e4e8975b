// CroCo's pre-training transforms for a pair (datasets/transforms.py, "crop224+acolor"):
// an independent random crop of each image to the training size, then asymmetric colour
// jitter (brightness, contrast and saturation factors in [0.6, 1.4], applied in a random order,
// drawn separately for each image), then ImageNet mean/std normalisation.
#pragma once

#include <torch/torch.h>

#include <vector>

#include "util/image.h"
#include "util/image_io.h"
#include "util/random.h"

namespace paircast {

struct AugmentOptions {
  int size = 224;
  bool colorJitter = true;
  double jitterLow = 0.6, jitterHigh = 1.4;
};

// Returns img1, img2 as normalised [3, S, S] float tensors. Images smaller than the crop are
// resized up first (bilinear). Deterministic for a given rng state.
std::pair<torch::Tensor, torch::Tensor> augmentPair(const Image8& a, const Image8& b,
                                                    const AugmentOptions& o, Rng& rng);

// The same from encoded images, with the same draws: each image's crop is drawn from its size
// in the header and only the crop is decoded (util/jpeg_decoder.h), so the result equals
// augmentPair of the decoded images. Images that are no JPEG, or smaller than the crop, are
// decoded whole. Throws paircast::Error naming the image when it does not decode.
std::pair<torch::Tensor, torch::Tensor> augmentEncodedPair(const EncodedImage& a,
                                                           const EncodedImage& b,
                                                           const AugmentOptions& o, Rng& rng);

// What augmentEncodedPairInto works in, made once per thread: the decoded crop, the image's
// three float planes and its grey plane.
struct AugmentScratch {
  explicit AugmentScratch(int size);
  int size;
  Image8 crop;                // the crop's 3 S S bytes, decoded as [3][S S]
  std::vector<float> planes;  // [3][S S]
  torch::Tensor gray;         // [S, S] float
};

// augmentEncodedPair into `out1` and `out2` ([3, S, S] float, contiguous: slots of a batch),
// with the same draws and, bit for bit, the same values, computed in `scratch` by fused float
// loops (see augment.cpp): nothing is allocated for a JPEG at least S x S (other images take
// augmentEncodedPair's path and are copied).
void augmentEncodedPairInto(const EncodedImage& a, const EncodedImage& b, const AugmentOptions& o,
                            Rng& rng, AugmentScratch& scratch, torch::Tensor out1,
                            torch::Tensor out2);

// augmentEncodedPair without the jitter and the normalisation: the two crops as uint8
// [3, S, S] into `out1` and `out2` (contiguous), and each image's jitter draws into `jitter1` and
// `jitter2` ([4] float: the order packed as 100 a + 10 b + c, then the brightness, contrast and
// saturation factors), with the same draws in the same order. Images that are no JPEG or are
// smaller than the crop are resized on the CPU as augmentEncodedPair does, and rounded.
void cropEncodedPairInto(const EncodedImage& a, const EncodedImage& b, const AugmentOptions& o,
                         Rng& rng, AugmentScratch& scratch, torch::Tensor out1, torch::Tensor out2,
                         float* jitter1, float* jitter2);

// The colour jitter and normalisation of uint8 crops [B, 3, S, S] with their draws [B, 4], on
// whatever device they are (a CUDA run's GPU): augmentEncodedPair's result within float
// rounding.
torch::Tensor jitterAndNormalizeBatch(const torch::Tensor& crops, const torch::Tensor& jitter);

// The colour jitter (when o.colorJitter; its order and factors drawn from rng) and the ImageNet
// normalisation of one cropped image, [3, S, S] in [0, 1].
torch::Tensor jitterAndNormalize(torch::Tensor x, const AugmentOptions& o, Rng& rng);

// One image: crop (x0, y0) of size S and the colour jitter, exposed for the tests.
torch::Tensor colorJitter(const torch::Tensor& rgb01, double brightness, double contrast,
                          double saturation, const int order[3]);

}  // namespace paircast
