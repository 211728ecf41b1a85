// Hexahedral element of a regular grid with linear isotropic elasticity.
//
// Quadrature: the 2x2x2 Gauss rule, the point of each octant weighted by the inside volume of that
// octant (the cut-cell weights). Full cells thus get the exact Gauss rule; cut cells integrate only
// their inside. At each point the 3x3 block coupling shape functions a and b is
//   K_ab = W (mu (g_a . g_b) I + mu g_b g_a^T + lambda g_a g_b^T),  g = grad N [1/m],
// the second derivative of the energy density mu eps:eps + lambda/2 tr(eps)^2.
//
// Two formulations (ElementFormulation):
// - trilinear: the 8 corner functions alone. Stiff in bending (parasitic shear) and near
//   incompressibility: a grid with few cells across a limb makes the body too stiff, and a fit
//   then lowers Young's modulus to make up for it.
// - incompatible modes (Wilson, Taylor et al. 1976): 3 bubble displacements 1 - xi_k^2 per axis
//   (9 internal degrees of freedom) enrich the strain and are condensed out of the element,
//   K = K_uu - K_ua K_aa^-1 K_au. The bubbles' gradients are taken relative to their weighted mean
//   over the element (Taylor's correction), so a uniform strain still stores exactly its energy in
//   cut cells as in full ones (the patch test), and the element has no modes beyond the 6 rigid
//   ones. K is no longer linear in (lambda, mu), but it is homogeneous of degree 1: scaling both
//   scales K, which the adjoint's derivative with respect to the Poisson ratio relies on
//   (ElementShearDerivative).
#pragma once

#include <Eigen/Core>
#include <array>

namespace softid::fem {

using Matrix24d = Eigen::Matrix<double, 24, 24>;
using Vector24d = Eigen::Matrix<double, 24, 1>;

enum class ElementFormulation { kTrilinear, kIncompatibleModes };
// "trilinear" | "incompatible_modes" (the names in job configs, flags and truth.json).
const char* ToString(ElementFormulation formulation);

// @param octant_volume inside volume per Gauss point (octant touching corner c) [m^3]
// @param h cell size [m]; lambda, mu Lame parameters [Pa], mu > 0
Matrix24d ElementStiffness(const std::array<double, 8>& octant_volume, double h, double lambda,
                           double mu,
                           ElementFormulation formulation = ElementFormulation::kTrilinear);

// d K / d mu at (lambda, mu) [m]: for the trilinear element ElementStiffness(w, h, 0, 1); for the
// incompatible-modes element it depends on lambda / mu. With it, by homogeneity,
// d K / d lambda = (K - mu d K / d mu) / lambda.
Matrix24d ElementShearDerivative(const std::array<double, 8>& octant_volume, double h,
                                 double lambda, double mu, ElementFormulation formulation);

// Shape-function gradients at the cell centre [1/m], used for the element's deformation gradient.
const std::array<Eigen::Vector3d, 8>& CentreGradientsUnitCell();

}  // namespace softid::fem
