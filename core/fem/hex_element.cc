#include "core/fem/hex_element.h"

#include <Eigen/Cholesky>
#include <cmath>

#include "core/geometry/regular_grid.h"

namespace softid::fem {
namespace {

// The 8 corner functions and the 3 bubbles of the incompatible-modes element.
constexpr int kCorners = 8;
constexpr int kBubbles = 3;
using Matrix33d = Eigen::Matrix<double, 3 * (kCorners + kBubbles), 3 * (kCorners + kBubbles)>;

// Gradients with respect to local coordinates (unit cell, xi in [0, 1]^3) at the Gauss point of
// each octant: the corners' trilinear functions, then the bubbles 1 - (2 xi_k - 1)^2.
struct GaussTable {
  std::array<std::array<Eigen::Vector3d, kCorners>, 8> corners;  // [point][corner]
  std::array<std::array<Eigen::Vector3d, kBubbles>, 8> bubbles;  // [point][axis]
  GaussTable() {
    const double offset = 0.5 / std::sqrt(3.0);
    for (int q = 0; q < 8; ++q) {
      const Eigen::Vector3d xi(0.5 + ((q & 1) ? offset : -offset),
                               0.5 + ((q & 2) ? offset : -offset),
                               0.5 + ((q & 4) ? offset : -offset));
      corners[q] = geometry::TrilinearGradients(xi);
      for (int k = 0; k < kBubbles; ++k)
        bubbles[q][k] = Eigen::Vector3d::Unit(k) * (-4.0 * (2.0 * xi[k] - 1.0));
    }
  }
};

const GaussTable& Table() {
  static const GaussTable table;
  return table;
}

// The stiffness over the first `functions` functions with gradients g (one set per point) of the
// energy density's (lambda, mu) weights; w: the points' weights [m] (volume / h^2).
template <int N>
Eigen::Matrix<double, 3 * N, 3 * N> Integrate(
    const std::array<std::array<Eigen::Vector3d, N>, 8>& g, const std::array<double, 8>& w,
    double lambda, double mu) {
  Eigen::Matrix<double, 3 * N, 3 * N> k = Eigen::Matrix<double, 3 * N, 3 * N>::Zero();
  for (int q = 0; q < 8; ++q) {
    if (w[q] == 0.0) continue;
    for (int a = 0; a < N; ++a) {
      for (int b = 0; b < N; ++b) {
        Eigen::Matrix3d block = (mu * g[q][a].dot(g[q][b])) * Eigen::Matrix3d::Identity();
        block.noalias() += mu * g[q][b] * g[q][a].transpose();
        block.noalias() += lambda * g[q][a] * g[q][b].transpose();
        k.template block<3, 3>(3 * a, 3 * b) += w[q] * block;
      }
    }
  }
  return k;
}

std::array<double, 8> PointWeights(const std::array<double, 8>& octant_volume, double h) {
  const double inv_h2 = 1.0 / (h * h);
  std::array<double, 8> w;
  for (int q = 0; q < 8; ++q) w[q] = octant_volume[q] * inv_h2;  // grad N = grad_xi N / h
  return w;
}

// Every function's gradients per point, the bubbles' relative to their weighted mean (Taylor's
// correction: a constant stress does no work on them, in any cut cell).
std::array<std::array<Eigen::Vector3d, kCorners + kBubbles>, 8> EnrichedGradients(
    const std::array<double, 8>& w) {
  const GaussTable& table = Table();
  double total = 0.0;
  std::array<Eigen::Vector3d, kBubbles> mean;
  mean.fill(Eigen::Vector3d::Zero());
  for (int q = 0; q < 8; ++q) {
    total += w[q];
    for (int k = 0; k < kBubbles; ++k) mean[k] += w[q] * table.bubbles[q][k];
  }
  std::array<std::array<Eigen::Vector3d, kCorners + kBubbles>, 8> g;
  for (int q = 0; q < 8; ++q) {
    for (int c = 0; c < kCorners; ++c) g[q][c] = table.corners[q][c];
    for (int k = 0; k < kBubbles; ++k)
      g[q][kCorners + k] = table.bubbles[q][k] - (total > 0.0 ? mean[k] / total : mean[k]);
  }
  return g;
}

// The enriched element's blocks: corner-corner (uu), corner-bubble (ua), bubble-bubble (aa).
struct EnrichedBlocks {
  Matrix24d uu;
  Eigen::Matrix<double, 24, 9> ua;
  Eigen::Matrix<double, 9, 9> aa;
};

EnrichedBlocks EnrichedStiffness(const std::array<std::array<Eigen::Vector3d, 11>, 8>& g,
                                 const std::array<double, 8>& w, double lambda, double mu) {
  const Matrix33d k = Integrate<kCorners + kBubbles>(g, w, lambda, mu);
  return {k.topLeftCorner<24, 24>(), k.topRightCorner<24, 9>(), k.bottomRightCorner<9, 9>()};
}

}  // namespace

const char* ToString(ElementFormulation formulation) {
  switch (formulation) {
    case ElementFormulation::kTrilinear: return "trilinear";
    case ElementFormulation::kIncompatibleModes: return "incompatible_modes";
  }
  return "invalid";  // a value cast from an out-of-range integer
}

Matrix24d ElementStiffness(const std::array<double, 8>& octant_volume, double h, double lambda,
                           double mu, ElementFormulation formulation) {
  const std::array<double, 8> w = PointWeights(octant_volume, h);
  if (formulation == ElementFormulation::kTrilinear)
    return Integrate<kCorners>(Table().corners, w, lambda, mu);
  const EnrichedBlocks k = EnrichedStiffness(EnrichedGradients(w), w, lambda, mu);
  const Eigen::Matrix<double, 9, 24> x = k.aa.ldlt().solve(k.ua.transpose());
  Matrix24d condensed = k.uu - k.ua * x;
  return 0.5 * (condensed + condensed.transpose());  // symmetric to the last bit
}

Matrix24d ElementShearDerivative(const std::array<double, 8>& octant_volume, double h,
                                 double lambda, double mu, ElementFormulation formulation) {
  const std::array<double, 8> w = PointWeights(octant_volume, h);
  if (formulation == ElementFormulation::kTrilinear)
    return Integrate<kCorners>(Table().corners, w, 0.0, 1.0);
  // K = K_uu - K_ua X with X = K_aa^-1 K_au; each block linear in (lambda, mu), d/dmu its shear
  // part S: dK = S_uu - S_ua X - X^T S_au + X^T S_aa X.
  const auto g = EnrichedGradients(w);
  const EnrichedBlocks k = EnrichedStiffness(g, w, lambda, mu);
  const EnrichedBlocks s = EnrichedStiffness(g, w, 0.0, 1.0);
  const Eigen::Matrix<double, 9, 24> x = k.aa.ldlt().solve(k.ua.transpose());
  const Eigen::Matrix<double, 24, 24> cross = s.ua * x;
  Matrix24d derivative = s.uu - cross - cross.transpose() + x.transpose() * s.aa * x;
  return 0.5 * (derivative + derivative.transpose());
}

const std::array<Eigen::Vector3d, 8>& CentreGradientsUnitCell() {
  static const std::array<Eigen::Vector3d, 8> gradients =
      geometry::TrilinearGradients(Eigen::Vector3d::Constant(0.5));
  return gradients;
}

}  // namespace softid::fem
