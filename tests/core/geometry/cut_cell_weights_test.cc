#include "core/geometry/cut_cell_weights.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <functional>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace softid::geometry {
namespace {

using std::numbers::pi;

Eigen::Vector3d CornerOffset(int c) {
  return Eigen::Vector3d(c & 1, (c >> 1) & 1, (c >> 2) & 1);
}

// Sums the cut-cell volumes of phi sampled at the nodes of an n^3 grid of cells of size h whose
// node (0,0,0) sits at `origin` [m].
double SumOfCellVolumes(const std::function<double(const Eigen::Vector3d&)>& phi,
                        const Eigen::Vector3d& origin, int n, double h) {
  double volume = 0.0;
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        std::array<double, 8> corner_phi;
        for (int c = 0; c < 8; ++c) {
          corner_phi[c] = phi(origin + h * (Eigen::Vector3d(i, j, k) + CornerOffset(c)));
        }
        volume += ComputeCutCellWeights(corner_phi, h).volume;
      }
    }
  }
  return volume;
}

void ExpectConsistentSums(const CutCellWeights& w, double tol) {
  double node_sum = 0.0, octant_sum = 0.0;
  for (int c = 0; c < 8; ++c) {
    node_sum += w.node_volume[c];
    octant_sum += w.octant_volume[c];
  }
  EXPECT_NEAR(node_sum, w.volume, tol);
  EXPECT_NEAR(octant_sum, w.volume, tol);
}

// A fully inside cell gives exactly h^3/8 per corner and octant.
TEST(CutCellWeights, FullCellIsExact) {
  const double h = 0.01;
  const CutCellWeights w = ComputeCutCellWeights({-1, -2, -3, -1e-9, -1, -1, -1, -5}, h);
  EXPECT_EQ(w.volume, h * h * h);
  for (int c = 0; c < 8; ++c) {
    EXPECT_EQ(w.node_volume[c], h * h * h / 8.0);
    EXPECT_EQ(w.octant_volume[c], h * h * h / 8.0);
  }
}

// A cell with no negative corner (zero counts as outside) has zero weights.
TEST(CutCellWeights, EmptyCellIsZero) {
  const CutCellWeights w = ComputeCutCellWeights({0, 1, 2, 0, 3, 1, 1, 0}, 0.01);
  EXPECT_EQ(w.volume, 0.0);
  for (int c = 0; c < 8; ++c) {
    EXPECT_EQ(w.node_volume[c], 0.0);
    EXPECT_EQ(w.octant_volume[c], 0.0);
  }
}

// phi = x - h/2: inside is the half x < h/2; int N_c = h^3 * (3/8 or 1/8) * 1/4 by x side.
TEST(CutCellWeights, HalfSpaceSplitsNodeVolumes) {
  const double h = 0.02, h3 = h * h * h;
  std::array<double, 8> phi;
  for (int c = 0; c < 8; ++c) phi[c] = h * CornerOffset(c).x() - 0.5 * h;
  const CutCellWeights w = ComputeCutCellWeights(phi, h);
  EXPECT_NEAR(w.volume, 0.5 * h3, 1e-12 * h3);
  for (int c = 0; c < 8; ++c) {
    const bool near_side = (c & 1) == 0;
    EXPECT_NEAR(w.node_volume[c], h3 * (near_side ? 3.0 / 32.0 : 1.0 / 32.0), 1e-12 * h3) << c;
    EXPECT_NEAR(w.octant_volume[c], near_side ? h3 / 8.0 : 0.0, 1e-12 * h3) << c;
  }
  ExpectConsistentSums(w, 1e-12 * h3);
}

// Fraction of the unit cube with x + y + z < t (piecewise cubic).
double UnitCubeBelowDiagonalPlane(double t) {
  if (t <= 0.0) return 0.0;
  if (t <= 1.0) return t * t * t / 6.0;
  if (t <= 2.0) return (t * t * t - 3.0 * std::pow(t - 1.0, 3)) / 6.0;
  if (t <= 3.0) return 1.0 - std::pow(3.0 - t, 3) / 6.0;
  return 1.0;
}

// Oblique plane x+y+z < 1.3 h (linear phi): cell and octant volumes are exact, and the node
// volumes of the plane and of its complement add up to h^3/8.
TEST(CutCellWeights, ObliquePlaneIsExact) {
  const double h = 0.01, h3 = h * h * h, s = 1.3;
  std::array<double, 8> phi, complement;
  for (int c = 0; c < 8; ++c) {
    phi[c] = h * (CornerOffset(c).sum() - s) / std::sqrt(3.0);
    complement[c] = -phi[c];
  }
  const CutCellWeights w = ComputeCutCellWeights(phi, h);
  const CutCellWeights wc = ComputeCutCellWeights(complement, h);
  EXPECT_NEAR(w.volume, UnitCubeBelowDiagonalPlane(s) * h3, 1e-12 * h3);
  for (int c = 0; c < 8; ++c) {
    // Octant c in its own unit coordinates: x' + y' + z' < 2 s - (dx + dy + dz).
    const double expected = UnitCubeBelowDiagonalPlane(2.0 * s - CornerOffset(c).sum()) * h3 / 8.0;
    EXPECT_NEAR(w.octant_volume[c], expected, 1e-12 * h3) << c;
    EXPECT_NEAR(w.node_volume[c] + wc.node_volume[c], h3 / 8.0, 1e-12 * h3) << c;
  }
  EXPECT_GT(w.node_volume[0], w.node_volume[7]);  // corner 0 is deepest inside
  ExpectConsistentSums(w, 1e-12 * h3);
}

// A generic cut cell (curved zero set) agrees with brute-force midpoint sampling on 120^3 points.
TEST(CutCellWeights, GenericCellMatchesBruteForce) {
  const std::array<double, 8> phi = {-0.3, 0.2, -0.1, 0.4, 0.05, 0.6, -0.2, -0.3};
  const CutCellWeights w = ComputeCutCellWeights(phi, 1.0);
  const int n = 120;
  std::array<double, 8> node{}, octant{};
  double volume = 0.0;
  const double dv = 1.0 / (double(n) * n * n);
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d xi = (Eigen::Vector3d(i, j, k) + Eigen::Vector3d::Constant(0.5)) / n;
        std::array<double, 8> weights;
        double value = 0.0;
        for (int c = 0; c < 8; ++c) {
          const Eigen::Vector3d d = CornerOffset(c);
          weights[c] = (d.x() > 0 ? xi.x() : 1 - xi.x()) * (d.y() > 0 ? xi.y() : 1 - xi.y()) *
                       (d.z() > 0 ? xi.z() : 1 - xi.z());
          value += weights[c] * phi[c];
        }
        if (value >= 0.0) continue;
        volume += dv;
        for (int c = 0; c < 8; ++c) node[c] += weights[c] * dv;
        octant[(2 * i >= n) + 2 * (2 * j >= n) + 4 * (2 * k >= n)] += dv;
      }
    }
  }
  EXPECT_NEAR(w.volume, volume, 1e-4);
  for (int c = 0; c < 8; ++c) {
    EXPECT_NEAR(w.node_volume[c], node[c], 1e-4) << c;
    EXPECT_NEAR(w.octant_volume[c], octant[c], 1e-4) << c;
  }
  ExpectConsistentSums(w, 1e-12);
}

// Sphere of radius 10 h from phi = |x| - r at the nodes. The trilinear interpolant of the convex
// |x| exceeds it by h^2/(6r) on average over the surface, so the exact volume of
// {trilinear phi < 0} is 4/3 pi r^3 (1 - h^2/(2 r^2)) to leading order (-0.5 % here); the
// integration must reproduce that to 0.02 % and lie within 0.6 % of the ball.
TEST(CutCellWeights, SphereVolumeOverCells) {
  const double h = 0.005;
  for (double r_over_h : {10.0, 10.37, 7.7}) {
    const double r = r_over_h * h;
    const int n = 2 * static_cast<int>(r_over_h) + 6;
    const Eigen::Vector3d origin = Eigen::Vector3d::Constant(-0.5 * n * h);
    const double volume =
        SumOfCellVolumes([r](const Eigen::Vector3d& p) { return p.norm() - r; }, origin, n, h);
    const double ball = 4.0 / 3.0 * pi * r * r * r;
    const double predicted = ball * (1.0 - 0.5 / (r_over_h * r_over_h));
    EXPECT_NEAR(volume, predicted, 2e-4 * ball) << "r = " << r_over_h << " h";
    if (r_over_h >= 10.0) {
      EXPECT_NEAR(volume, ball, 6e-3 * ball) << "r = " << r_over_h << " h";
    }
  }
}

// Weights are consistent on a generic cut cell and scale with h^3.
TEST(CutCellWeights, ConsistentAndScaleWithCellSize) {
  const std::array<double, 8> phi = {-0.3, 0.2, -0.1, 0.4, 0.05, 0.6, -0.2, 0.3};
  const CutCellWeights a = ComputeCutCellWeights(phi, 1.0);
  std::array<double, 8> scaled;
  for (int c = 0; c < 8; ++c) scaled[c] = 0.01 * phi[c];
  const CutCellWeights b = ComputeCutCellWeights(scaled, 0.01);
  ExpectConsistentSums(a, 1e-12);
  EXPECT_GT(a.volume, 0.0);
  EXPECT_LT(a.volume, 1.0);
  EXPECT_NEAR(b.volume, a.volume * 1e-6, 1e-15);
  for (int c = 0; c < 8; ++c) {
    EXPECT_GE(a.node_volume[c], 0.0);
    EXPECT_LE(a.octant_volume[c], 0.125);
    EXPECT_NEAR(b.node_volume[c], a.node_volume[c] * 1e-6, 1e-15);
  }
  EXPECT_THROW(ComputeCutCellWeights(phi, 0.0), std::invalid_argument);
}

}  // namespace
}  // namespace softid::geometry

namespace softid::geometry {
namespace {

// Corners exactly on the surface (phi = 0 or round-off like -7e-18, as on grid-aligned boxes) give
// finite weights: a face-aligned half-inside cell and a corner-touching one.
TEST(CutCellWeights, FiniteForCornersOnTheSurface) {
  const double h = 0.025;
  const std::array<double, 8> face = {0, -6.94e-18, 0, -6.94e-18, 0, -0.025, 0, -0.025};
  const std::array<double, 8> edge = {-6.94e-18, -6.94e-18, 1.39e-17, 1.39e-17,
                                      -0.025,    -0.025,    1.39e-17, 1.39e-17};
  for (const auto& phi : {face, edge}) {
    const CutCellWeights w = ComputeCutCellWeights(phi, h);
    EXPECT_TRUE(std::isfinite(w.volume));
    EXPECT_GE(w.volume, 0.0);
    EXPECT_LE(w.volume, h * h * h);
    for (int c = 0; c < 8; ++c) {
      EXPECT_TRUE(std::isfinite(w.node_volume[c]));
      EXPECT_TRUE(std::isfinite(w.octant_volume[c]));
    }
  }
}

}  // namespace
}  // namespace softid::geometry

namespace softid::geometry {
namespace {

// Phi of `f` on the (n + 1)^3 lattice of the unit-less cell [0, h]^3.
std::vector<double> Lattice(const std::function<double(const Eigen::Vector3d&)>& f, int n,
                            double h) {
  std::vector<double> values;
  for (int k = 0; k <= n; ++k) {
    for (int j = 0; j <= n; ++j) {
      for (int i = 0; i <= n; ++i) values.push_back(f(h / n * Eigen::Vector3d(i, j, k)));
    }
  }
  return values;
}

// Where phi is linear the lattice adds nothing: every n gives the corners' weights.
TEST(CutCellWeights, ALatticeOfAPlaneGivesTheCornersWeights) {
  const double h = 0.02;
  const Eigen::Vector3d normal = Eigen::Vector3d(0.3, -0.5, 0.8).normalized();
  const auto plane = [&](const Eigen::Vector3d& x) { return normal.dot(x) - 0.004; };
  const CutCellWeights corners = ComputeCutCellWeights(Lattice(plane, 1, h), 1, h);
  ASSERT_GT(corners.volume, 0.1 * h * h * h);
  ASSERT_LT(corners.volume, 0.9 * h * h * h);
  for (int n : {2, 4, 8}) {
    const CutCellWeights w = ComputeCutCellWeights(Lattice(plane, n, h), n, h);
    EXPECT_NEAR(w.volume, corners.volume, 1e-12 * h * h * h) << n;
    for (int c = 0; c < 8; ++c) {
      EXPECT_NEAR(w.node_volume[c], corners.node_volume[c], 1e-12 * h * h * h) << n;
      EXPECT_NEAR(w.octant_volume[c], corners.octant_volume[c], 1e-12 * h * h * h) << n;
    }
  }
}

// A box's corner inside the cell ({x, y, z < 0.82 h}: 0.551 of it) is rounded at the scale of the
// lattice: the corners alone give about 0.2 of the cell, a lattice of h / 8 within 1 % of 0.551.
TEST(CutCellWeights, ALatticeFollowsABoxCorner) {
  const double h = 0.01, a = 0.82 * h;
  const auto box_corner = [&](const Eigen::Vector3d& x) {
    const Eigen::Vector3d q = x - Eigen::Vector3d::Constant(a);
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  };
  const double exact = a * a * a;
  double previous_error = exact;
  for (int n : {1, 2, 4, 8}) {
    const CutCellWeights w = ComputeCutCellWeights(Lattice(box_corner, n, h), n, h);
    ExpectConsistentSums(w, 1e-15);
    const double error = exact - w.volume;
    EXPECT_GT(error, 0.0) << n << ": the rounding only removes";
    // Each halving of the lattice's spacing at least halves the rounding, down to the planar
    // leaves' own error at h / 8.
    if (n > 1 && n < 8) EXPECT_LT(error, 0.5 * previous_error) << n;
    previous_error = error;
  }
  EXPECT_LT(previous_error, 0.01 * exact);
  EXPECT_LT(ComputeCutCellWeights(Lattice(box_corner, 1, h), 1, h).volume, 0.45 * exact);
}

TEST(CutCellWeights, ALatticeOfTheWrongSizeOrSpacingIsRejected) {
  const std::vector<double> lattice(27, -1.0);
  EXPECT_DOUBLE_EQ(ComputeCutCellWeights(lattice, 2, 0.01).volume, 1e-6);
  EXPECT_THROW(ComputeCutCellWeights(lattice, 3, 0.01), std::invalid_argument);
  EXPECT_THROW(ComputeCutCellWeights(lattice, 4, 0.01), std::invalid_argument);
  EXPECT_THROW(ComputeCutCellWeights(lattice, 2, 0.0), std::invalid_argument);
}

}  // namespace
}  // namespace softid::geometry
