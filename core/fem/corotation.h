// Element rotations for the corotated formulation: the rotation of the polar decomposition of the
// deformation gradient at the cell centre. Inverted elements (det F < 0) get the closest proper
// rotation (the smallest singular direction flipped), which is continuous through inversion,
// unlike switching to the identity.
#pragma once

#include <Eigen/Core>
#include <array>

namespace softid::fem {

// F = sum_c x_c grad N_c^T with grad N_c = centre_gradients_unit[c] / h.
// @param x deformed corner positions [m]
Eigen::Matrix3d DeformationGradient(const std::array<Eigen::Vector3d, 8>& x, double h);

// Rotation factor R of F = R S (S symmetric); R is proper (det R = +1).
Eigen::Matrix3d PolarRotation(const Eigen::Matrix3d& f);

// [v]x: the matrix of the cross product v x (.). Inline: the element assembly calls it 24 times
// per element.
inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

}  // namespace softid::fem
