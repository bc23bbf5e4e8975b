// Cross-view completion of one pair, for looking at what a model learnt: the figure-2-style
// grid of CroCo's paper (reference view, masked input, reconstruction, target).
#pragma once

#include <optional>
#include <string>

#include "model/croco_config.h"
#include "model/croco_net.h"
#include "util/image.h"

namespace paircast {

struct ReconstructOptions {
  std::string checkpoint, image1, image2;
  std::string maskFile;  // 0/1 per patch, row-major, 1 = masked; empty: random
  uint64_t seed = 0;
  std::optional<CroCoConfig> config;  // for checkpoints without our args (official ones)
  std::string amp = "auto";           // the forward's precision on the CPU: auto, bf16 or none
};

struct Reconstruction {
  Image8 grid;               // [S, 4 S, 3]: reference | masked input | reconstruction | target
  torch::Tensor prediction;  // [N, P] raw head output
  double loss = 0;           // masked MSE (norm_pix) of this pair
};

// Loads the checkpoint, runs the model on the pair and builds the grid. Images are resized to
// the model's size and normalised with ImageNet mean and std. Throws paircast::Error naming the
// bad file (checkpoint, image, mask) on bad input.
Reconstruction reconstruct(const ReconstructOptions& options);
// The same on a model in hand, images already [1, 3, S, S] normalised, mask [1, N] bool. With
// img2 undefined the model completes img1 alone (a mae model's task), and the reference tile is
// grey.
Reconstruction reconstructWith(CroCoNet& model, const torch::Tensor& img1,
                               const torch::Tensor& img2, const torch::Tensor& mask);

// The model a checkpoint describes: its own args (ours), else `fallback` checked against the
// tensor shapes. Throws when neither applies. `task`, when given, is set to what the model was
// trained on: "croco", or "mae" (pretrain --task mae: completion without a reference).
CroCoNet modelFromCheckpoint(const std::string& path, const std::optional<CroCoConfig>& fallback,
                             std::string* task = nullptr);

// Writes a float32 .npy file of a 2-D tensor.
void writeNpy(const std::string& path, const torch::Tensor& t);
// An 8-bit RGB image as a normalised [1, 3, S, S] tensor, resized (bilinear) to S x S.
torch::Tensor imageTensor(const Image8& img, int size);

}  // namespace paircast
