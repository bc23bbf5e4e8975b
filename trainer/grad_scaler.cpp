#include "trainer/grad_scaler.h"

#include "util/error.h"

namespace paircast {

GradScaler::GradScaler(bool enabled, double initScale, int growthInterval, double growthFactor,
                       double backoffFactor)
    : enabled_(enabled),
      scale_(initScale),
      growthFactor_(growthFactor),
      backoffFactor_(backoffFactor),
      growthInterval_(growthInterval) {
  if (!(initScale > 0) || growthInterval < 1 || !(growthFactor > 1) || !(backoffFactor > 0) ||
      !(backoffFactor < 1))
    throw Error("invalid loss-scale settings");
}

torch::Tensor GradScaler::scaleLoss(const torch::Tensor& loss) const {
  return enabled_ ? loss * scale_ : loss;
}

bool GradScaler::unscale(const std::vector<torch::Tensor>& params) {
  if (!enabled_) return true;
  const double inv = 1.0 / scale_;
  torch::Tensor bad;  // one device-side flag, read once: a single synchronisation per step
  for (const auto& p : params) {
    if (!p.grad().defined()) continue;
    torch::Tensor g = p.grad();
    g.mul_(inv);
    auto nonFinite = torch::logical_not(torch::isfinite(g)).any();
    bad = bad.defined() ? torch::logical_or(bad, nonFinite) : nonFinite;
  }
  return !bad.defined() || !bad.item<bool>();
}

void GradScaler::update(bool stepWasFinite) {
  if (!enabled_) return;
  if (!stepWasFinite) {
    scale_ *= backoffFactor_;
    tracker_ = 0;
  } else if (++tracker_ >= growthInterval_) {
    scale_ *= growthFactor_;
    tracker_ = 0;
  }
}

nlohmann::json GradScaler::state() const {
  return {{"scale", scale_},
          {"growth_factor", growthFactor_},
          {"backoff_factor", backoffFactor_},
          {"growth_interval", growthInterval_},
          {"_growth_tracker", tracker_}};
}

void GradScaler::restore(const nlohmann::json& s) {
  if (!s.is_object()) return;
  scale_ = s.value("scale", scale_);
  tracker_ = s.value("_growth_tracker", tracker_);
  if (!(scale_ > 0) || !std::isfinite(scale_) || tracker_ < 0)
    throw Error("the checkpoint's loss scale is invalid");
}

}  // namespace paircast
