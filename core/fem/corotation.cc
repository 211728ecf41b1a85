#include "core/fem/corotation.h"

#include <Eigen/LU>
#include <Eigen/SVD>

#include "core/fem/hex_element.h"

namespace softid::fem {

Eigen::Matrix3d DeformationGradient(const std::array<Eigen::Vector3d, 8>& x, double h) {
  const auto& g = CentreGradientsUnitCell();
  Eigen::Matrix3d f = Eigen::Matrix3d::Zero();
  for (int c = 0; c < 8; ++c) f.noalias() += x[c] * g[c].transpose();
  return f / h;
}

Eigen::Matrix3d PolarRotation(const Eigen::Matrix3d& f) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(f, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU();
  const Eigen::Matrix3d& v = svd.matrixV();
  if ((u * v.transpose()).determinant() < 0.0) u.col(2) = -u.col(2);  // smallest singular value
  return u * v.transpose();
}

}  // namespace softid::fem
