// A dynamic loss scale for fp16 training, as torch.cuda.amp.GradScaler: the loss is multiplied
// by `scale` before backward; before the optimizer step the gradients are divided by it and
// checked. A non-finite gradient skips the step and halves the scale; `growthInterval` clean
// steps in a row double it.
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>
#include <vector>

namespace paircast {

class GradScaler {
 public:
  explicit GradScaler(bool enabled, double initScale = 65536.0, int growthInterval = 2000,
                      double growthFactor = 2.0, double backoffFactor = 0.5);

  bool enabled() const { return enabled_; }
  double scale() const { return scale_; }
  // loss * scale (the loss itself when disabled).
  torch::Tensor scaleLoss(const torch::Tensor& loss) const;
  // Divides the gradients by the scale in place. Returns false when one of them is not finite:
  // the caller skips the optimizer step. Does nothing and returns true when disabled.
  bool unscale(const std::vector<torch::Tensor>& params);
  // After each optimizer step (or skip): grows or backs off the scale.
  void update(bool stepWasFinite);

  // GradScaler.state_dict()'s keys: scale, growth_factor, backoff_factor, growth_interval,
  // _growth_tracker.
  nlohmann::json state() const;
  void restore(const nlohmann::json& state);

 private:
  bool enabled_;
  double scale_, growthFactor_, backoffFactor_;
  int growthInterval_, tracker_ = 0;
};

}  // namespace paircast
