// Smoothly truncated squared distance (Tukey's biweight) for the sparse surface constraint cost:
//   rho(phi) = phi_max^2 / 6 * (1 - (1 - (phi / phi_max)^2)^3)   for |phi| < phi_max,
//   rho(phi) = phi_max^2 / 6                                     otherwise.
// Near 0 it is 0.5 phi^2 - ..., so small residuals are plain least squares; it is C^2 at
// |phi| = phi_max, so an outlier (a point on no part of the object, or on a part the simulation
// misplaces) reaches the constant smoothly and stops pulling. The paper truncates 0.5 phi^2 at a
// few voxels; a hard clamp would make the cost jump and its gradient discontinuous.
#pragma once

#include <cmath>

namespace softid::cost {

// rho(phi) [m^2] for phi [m] and phi_max > 0 [m].
inline double TukeyLoss(double phi, double phi_max) {
  const double q = (phi / phi_max) * (phi / phi_max);
  if (!(q < 1.0)) return phi_max * phi_max / 6.0;
  const double w = 1.0 - q;
  return phi_max * phi_max / 6.0 * (1.0 - w * w * w);
}

// d rho / d phi [m] = phi (1 - (phi / phi_max)^2)^2 inside, 0 outside.
inline double TukeyLossDerivative(double phi, double phi_max) {
  const double q = (phi / phi_max) * (phi / phi_max);
  if (!(q < 1.0)) return 0.0;
  const double w = 1.0 - q;
  return phi * w * w;
}

}  // namespace softid::cost
