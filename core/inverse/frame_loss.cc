#include "core/inverse/frame_loss.h"

namespace softid::inverse {

const char* ToString(FrameLossKind kind) {
  return kind == FrameLossKind::kCauchy ? "cauchy" : "squared";
}

FrameLoss MakeFrameLoss(FrameLossKind kind, double noise_multiple, double depth_noise_m) {
  FrameLoss loss;
  if (kind == FrameLossKind::kCauchy) {
    const double spread_m = noise_multiple * depth_noise_m;
    loss.scale_m2 = 0.5 * spread_m * spread_m;
  }
  return loss;
}

}  // namespace softid::inverse
