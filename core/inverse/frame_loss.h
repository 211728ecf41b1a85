// How the frames' costs add up to the cost a fit minimises.
//
// Least squares ("squared", the default) counts a frame by its cost C_k: a frame the model cannot
// reproduce (physics it leaves out, or the discretisation's drift late in a slide) weighs as many
// times more as it misfits, and a parameter far from the truth can win by trading a large
// relative loss on the frames the model fits for a small relative gain on those it does not.
// A soft cube sliding down a ramp of an independent FEM code: frames 16-30 misfit at 13 x the
// cost of frames 0-15; E = 64.5 kPa fitted them 8 % better than E = 28.2 kPa, and frames 0-15
// 80 % worse, and won by 1 % over every frame (the reference's modulus is 29.1 kPa).
//
// "cauchy" counts frame k by b log(1 + C_k / b) (Cauchy's robust loss, applied per frame): equal
// to C_k while C_k << b, so a fit whose frames all match to the depth noise is the least-squares
// fit; a frame with C_k >> b counts by its relative change. Its gradient is the least-squares one
// with frame k weighted by 1 / (1 + C_k / b): the maximum-likelihood weighting when each frame
// carries a model error of its own variance (iteratively reweighted least squares).
// b = (k sigma)^2 / 2 with sigma the capture's depth noise: C_k is a mean of phi^2 / 2 over the
// frame's points, so a frame whose points lie k sigma from the surface on average counts half.
#pragma once

#include <cmath>

namespace softid::inverse {

enum class FrameLossKind { kSquared, kCauchy };
// "squared" | "cauchy" (the JSON names).
const char* ToString(FrameLossKind kind);

struct FrameLoss {
  // b [m^2]; 0 = least squares.
  double scale_m2 = 0.0;

  bool IsSquared() const { return !(scale_m2 > 0.0); }
  // What frame cost c [m^2] adds to the cost [m^2].
  double Value(double c) const { return IsSquared() ? c : scale_m2 * std::log1p(c / scale_m2); }
  // d Value / d c [-], in (0, 1].
  double Weight(double c) const { return IsSquared() ? 1.0 : 1.0 / (1.0 + c / scale_m2); }
  // Value(c) / c [-], in (0, 1]: its limit 1 at c = 0 (below 1e-8 b, where log1p(x) / x = 1 to
  // 1e-8; avoids 0 / 0).
  double ValueOverCost(double c) const {
    return IsSquared() || c < 1e-8 * scale_m2 ? 1.0 : Value(c) / c;
  }
};

// The loss of `kind` for a capture of depth noise `depth_noise_m` [m]: b = (noise_multiple x
// depth_noise_m)^2 / 2 for kCauchy; least squares for kSquared.
FrameLoss MakeFrameLoss(FrameLossKind kind, double noise_multiple, double depth_noise_m);

}  // namespace softid::inverse
