// Trilinear hexahedral element of a regular grid with linear isotropic elasticity.
//
// Quadrature: the 2x2x2 Gauss rule, the point of each octant weighted by the inside volume of that
// octant (the cut-cell weights). Full cells thus get the exact Gauss rule; cut cells integrate only
// their inside. At each point the 3x3 block coupling corners a and b is
//   K_ab = W (mu (g_a . g_b) I + mu g_b g_a^T + lambda g_a g_b^T),  g = grad N [1/m],
// the second derivative of the energy density mu eps:eps + lambda/2 tr(eps)^2.
#pragma once

#include <Eigen/Core>
#include <array>

namespace softid::fem {

using Matrix24d = Eigen::Matrix<double, 24, 24>;
using Vector24d = Eigen::Matrix<double, 24, 1>;

// @param octant_volume inside volume per Gauss point (octant touching corner c) [m^3]
// @param h cell size [m]; lambda, mu Lame parameters [Pa]
Matrix24d ElementStiffness(const std::array<double, 8>& octant_volume, double h, double lambda,
                           double mu);

// Shape-function gradients at the cell centre [1/m], used for the element's deformation gradient.
const std::array<Eigen::Vector3d, 8>& CentreGradientsUnitCell();

}  // namespace softid::fem
