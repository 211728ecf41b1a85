#include "core/fem/hex_element.h"

#include <cmath>

#include "core/geometry/regular_grid.h"

namespace softid::fem {
namespace {

// Gradients with respect to local coordinates of the 8 shape functions at the Gauss point of each
// octant (unit cell).
struct GaussTable {
  std::array<std::array<Eigen::Vector3d, 8>, 8> gradients;  // [point][corner]
  GaussTable() {
    const double offset = 0.5 / std::sqrt(3.0);
    for (int q = 0; q < 8; ++q) {
      const Eigen::Vector3d xi(0.5 + ((q & 1) ? offset : -offset),
                               0.5 + ((q & 2) ? offset : -offset),
                               0.5 + ((q & 4) ? offset : -offset));
      gradients[q] = geometry::TrilinearGradients(xi);
    }
  }
};

const GaussTable& Table() {
  static const GaussTable table;
  return table;
}

}  // namespace

Matrix24d ElementStiffness(const std::array<double, 8>& octant_volume, double h, double lambda,
                           double mu) {
  Matrix24d k = Matrix24d::Zero();
  const double inv_h2 = 1.0 / (h * h);
  for (int q = 0; q < 8; ++q) {
    const double w = octant_volume[q] * inv_h2;  // grad N = grad_xi N / h
    if (w == 0.0) continue;
    const auto& g = Table().gradients[q];
    for (int a = 0; a < 8; ++a) {
      for (int b = 0; b < 8; ++b) {
        Eigen::Matrix3d block = (mu * g[a].dot(g[b])) * Eigen::Matrix3d::Identity();
        block.noalias() += mu * g[b] * g[a].transpose();
        block.noalias() += lambda * g[a] * g[b].transpose();
        k.block<3, 3>(3 * a, 3 * b) += w * block;
      }
    }
  }
  return k;
}

const std::array<Eigen::Vector3d, 8>& CentreGradientsUnitCell() {
  static const std::array<Eigen::Vector3d, 8> gradients =
      geometry::TrilinearGradients(Eigen::Vector3d::Constant(0.5));
  return gradients;
}

}  // namespace softid::fem
