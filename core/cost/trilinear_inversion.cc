#include "core/cost/trilinear_inversion.h"

#include <Eigen/LU>
#include <cmath>

namespace softid::cost {

TrilinearInversion InvertTrilinearMap(const std::array<Eigen::Vector3d, 8>& corners,
                                      const Eigen::Vector3d& x,
                                      const TrilinearInversionOptions& options) {
  // Monomial form relative to corner 0 (smaller numbers, less cancellation far from the origin):
  // x(xi) - x_0 = a1 xi + a2 eta + a3 zeta + a12 xi eta + a13 xi zeta + a23 eta zeta
  //               + a123 xi eta zeta.
  const Eigen::Vector3d& x0 = corners[0];
  const Eigen::Vector3d a1 = corners[1] - x0;
  const Eigen::Vector3d a2 = corners[2] - x0;
  const Eigen::Vector3d a3 = corners[4] - x0;
  const Eigen::Vector3d a12 = corners[3] - corners[2] - a1;
  const Eigen::Vector3d a13 = corners[5] - corners[4] - a1;
  const Eigen::Vector3d a23 = corners[6] - corners[4] - a2;
  const Eigen::Vector3d a123 = corners[7] - corners[6] - corners[5] + corners[4] - a12;
  const Eigen::Vector3d target = x - x0;
  // Scale for the singularity test: the cell's edge length cubed.
  const double scale = a1.norm() * a2.norm() * a3.norm();

  TrilinearInversion result;
  Eigen::Vector3d& xi = result.xi;
  for (int it = 0; it < options.max_iterations; ++it) {
    const double s = xi.x(), t = xi.y(), r = xi.z();
    const Eigen::Vector3d f = a1 * s + a2 * t + a3 * r + a12 * (s * t) + a13 * (s * r) +
                              a23 * (t * r) + a123 * (s * t * r) - target;
    Eigen::Matrix3d& jac = result.jacobian;
    jac.col(0) = a1 + a12 * t + a13 * r + a123 * (t * r);
    jac.col(1) = a2 + a12 * s + a23 * r + a123 * (s * r);
    jac.col(2) = a3 + a13 * s + a23 * t + a123 * (s * t);
    const double det = jac.determinant();
    if (!(std::abs(det) > 1e-14 * scale)) return result;  // singular, degenerate or NaN
    const Eigen::Vector3d step = jac.inverse() * f;
    xi -= step;
    result.iterations = it + 1;
    if (!(xi.cwiseAbs().maxCoeff() < 1e3)) return result;
    if (step.cwiseAbs().maxCoeff() <= options.step_tolerance) {
      // Jacobian at the returned xi, for the implicit-function derivative.
      const double s1 = xi.x(), t1 = xi.y(), r1 = xi.z();
      jac.col(0) = a1 + a12 * t1 + a13 * r1 + a123 * (t1 * r1);
      jac.col(1) = a2 + a12 * s1 + a23 * r1 + a123 * (s1 * r1);
      jac.col(2) = a3 + a13 * s1 + a23 * t1 + a123 * (s1 * t1);
      result.converged = true;
      return result;
    }
  }
  return result;
}

}  // namespace softid::cost
