#include "core/geometry/grid_alignment.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "core/geometry/primitives.h"

namespace softid::geometry {
namespace {

using std::numbers::pi;

TriangleMesh Turned(TriangleMesh mesh, const Eigen::Matrix3d& turn) {
  for (Eigen::Vector3d& x : mesh.vertices) x = turn * x;
  return mesh;
}

Eigen::Matrix3d Turn(double angle_deg, const Eigen::Vector3d& axis) {
  return Eigen::AngleAxisd(angle_deg * pi / 180.0, axis.normalized()).toRotationMatrix();
}

double AngleBetween(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

// A box along the axes has every face normal to one: score 1, and the mesh's own axes are kept
// exactly (nothing to gain, and the nearest of the grid's equivalent frames is the identity).
TEST(GridAlignment, ABoxAlongTheAxesKeepsThem) {
  const TriangleMesh box = MakeBox(Eigen::Vector3d(0.3, 0.2, 0.1), 0.03);
  EXPECT_NEAR(AxisAlignmentScore(box, Eigen::Matrix3d::Identity()), 1.0, 1e-12);
  const GridAlignment alignment = AlignGridToSurface(box);
  EXPECT_EQ(alignment.mesh_from_grid, Eigen::Matrix3d::Identity());
  EXPECT_NEAR(alignment.score, 1.0, 1e-12);
}

// Turned by 25 degrees about y, the four faces around y score cos^4 + sin^4 of the angle and the
// two normal to y score 1; the search finds the turn again to a micro-radian.
TEST(GridAlignment, FindsTheFacesOfATurnedBox) {
  const Eigen::Matrix3d turn = Turn(25.0, Eigen::Vector3d::UnitY());
  const TriangleMesh box = Turned(MakeBox(Eigen::Vector3d(0.1, 0.1, 0.1), 0.02), turn);
  const double c = std::cos(25.0 * pi / 180.0), s = std::sin(25.0 * pi / 180.0);
  const double expected = (2.0 + 4.0 * (std::pow(c, 4) + std::pow(s, 4))) / 6.0;
  const GridAlignment alignment = AlignGridToSurface(box);
  EXPECT_NEAR(alignment.identity_score, expected, 1e-12);
  EXPECT_NEAR(alignment.score, 1.0, 1e-10);
  EXPECT_LT(AngleBetween(alignment.mesh_from_grid, turn), 1e-5);
  EXPECT_NEAR(alignment.mesh_from_grid.determinant(), 1.0, 1e-12);
}

// A turn about an oblique axis, of a box with unequal sides: the grid's axes go back onto the
// faces (the frame nearest the mesh's axes of the 24 equivalent ones).
TEST(GridAlignment, FindsAnObliqueTurn) {
  const Eigen::Matrix3d turn = Turn(37.0, Eigen::Vector3d(0.3, -0.5, 0.8));
  const TriangleMesh box = Turned(MakeBox(Eigen::Vector3d(0.12, 0.08, 0.05), 0.01), turn);
  const GridAlignment alignment = AlignGridToSurface(box);
  EXPECT_NEAR(alignment.score, 1.0, 1e-10);
  EXPECT_LT(alignment.identity_score, 0.9);
  EXPECT_LT(AngleBetween(alignment.mesh_from_grid, turn), 1e-5);
}

// Normals spread evenly over the sphere average sum_a n_a^4 = 3/5 in every orientation; a fine
// icosphere's score barely depends on how the grid lies.
TEST(GridAlignment, ABallScoresAlikeInEveryOrientation) {
  const TriangleMesh ball = MakeSphere(0.1, 4);
  const GridAlignment alignment = AlignGridToSurface(ball);
  EXPECT_NEAR(alignment.identity_score, 0.6, 0.01);
  EXPECT_LT(alignment.score - alignment.identity_score, 0.002);
  EXPECT_GE(alignment.score, alignment.identity_score);
}

// The grid's bounds of a turned box are the box's own when the grid follows it.
TEST(GridAlignment, BoundsInTheGridsFrame) {
  const Eigen::Matrix3d turn = Turn(30.0, Eigen::Vector3d::UnitZ());
  const TriangleMesh box = Turned(MakeBox(Eigen::Vector3d(0.3, 0.2, 0.1), 0.05), turn);
  EXPECT_TRUE(BoundsInGrid(box, turn).sizes().isApprox(Eigen::Vector3d(0.3, 0.2, 0.1), 1e-12));
  EXPECT_GT(BoundsInGrid(box, Eigen::Matrix3d::Identity()).sizes().x(), 0.3);
}

TEST(GridAlignment, AMeshWithoutAreaKeepsItsAxes) {
  TriangleMesh flat;
  flat.vertices = {Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), 2 * Eigen::Vector3d::UnitX()};
  flat.triangles = {Eigen::Vector3i(0, 1, 2)};
  const GridAlignment alignment = AlignGridToSurface(flat);
  EXPECT_EQ(alignment.mesh_from_grid, Eigen::Matrix3d::Identity());
  EXPECT_EQ(alignment.score, 0.0);
}

}  // namespace
}  // namespace softid::geometry
