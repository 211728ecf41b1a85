// Inversion of the trilinear map of a deformed hexahedral cell: find local coordinates xi with
// x(xi) = sum_c N_c(xi) x_c = x for the cell's deformed corners x_c (corner c = dx + 2dy + 4dz, as
// geometry::RegularGrid::CellNodes). The map is a polynomial in xi of degree 1 per axis, so Newton
// from the cell centre converges in a handful of iterations for the mildly distorted cells of an
// elastic body (method-notes Sec. 4).
#pragma once

#include <Eigen/Core>
#include <array>

namespace softid::cost {

struct TrilinearInversion {
  bool converged = false;
  Eigen::Vector3d xi = Eigen::Vector3d::Constant(0.5);  // local coordinates [-]
  // dx/dxi at the returned xi [m]; the implicit-function derivative of xi needs its inverse.
  Eigen::Matrix3d jacobian = Eigen::Matrix3d::Zero();
  int iterations = 0;
};

struct TrilinearInversionOptions {
  int max_iterations = 20;  // Newton iterations [-], >= 1
  // Converged when the last Newton step is below this in local coordinates (a fraction of the
  // cell). Convergence is quadratic, so the step after a 1e-12 step is at round-off: the returned
  // xi is accurate to machine precision, which finite-difference checks of the cost need.
  double step_tolerance = 1e-12;  // [-], > 0
};

// Newton from xi = (0.5, 0.5, 0.5). Not converged (within max_iterations) when the Jacobian becomes
// singular or the iterate runs off (|xi| > 1e3): such a point lies far outside the cell or the
// cell is degenerate. Converged results may lie outside [0,1]^3; the caller decides.
TrilinearInversion InvertTrilinearMap(const std::array<Eigen::Vector3d, 8>& corners,
                                      const Eigen::Vector3d& x,
                                      const TrilinearInversionOptions& options = {});

}  // namespace softid::cost
