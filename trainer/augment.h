// CroCo's pre-training transforms for a pair (datasets/transforms.py, "crop224+acolor"):
// an independent random crop of each image to the training size, then asymmetric colour
// jitter (brightness, contrast and saturation factors in [0.6, 1.4], applied in a random order,
// drawn separately for each image), then ImageNet mean/std normalisation.
#pragma once

#include <torch/torch.h>

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

// One image: crop (x0, y0) of size S and the colour jitter, exposed for the tests.
torch::Tensor colorJitter(const torch::Tensor& rgb01, double brightness, double contrast,
                          double saturation, const int order[3]);

}  // namespace paircast
