#include "core/diagnosis/screening.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/geometry/primitives.h"
#include "core/geometry/signed_distance_field.h"

namespace softid::diagnosis {
namespace {

fem::HexMesh BoxMesh(const Eigen::Vector3d& size, const Eigen::Isometry3d& pose) {
  geometry::TriangleMesh box = geometry::MakeBox(size, 0.02);
  for (auto& v : box.vertices) v = pose * v;
  geometry::SignedDistanceOptions options;
  options.cells_along_longest_side = 12;
  Result<geometry::SignedDistanceField> sdf = geometry::ComputeSignedDistanceField(box, options);
  EXPECT_TRUE(sdf.ok()) << sdf.status().ToString();
  return fem::BuildHexMesh(*sdf, 0.05);
}

// |a . b| close to 1: the same axis up to its sign.
double Alignment(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::abs(a.dot(b));
}

// A bar's long axis has the largest second moment; its square section leaves the other two to
// the world axes, which are then exactly y and z.
TEST(PrincipalAxes, BarSquareToTheWorld) {
  const auto axes = PrincipalAxes(BoxMesh(Eigen::Vector3d(0.16, 0.08, 0.08),
                                          Eigen::Isometry3d(Eigen::Translation3d(0.1, 0, 0.2))));
  EXPECT_GT(Alignment(axes[2], Eigen::Vector3d::UnitX()), 1.0 - 1e-9);
  EXPECT_GT(
      Alignment(axes[0], Eigen::Vector3d::UnitY()) + Alignment(axes[1], Eigen::Vector3d::UnitY()),
      1.0 - 1e-9);
  EXPECT_GT(
      Alignment(axes[0], Eigen::Vector3d::UnitZ()) + Alignment(axes[1], Eigen::Vector3d::UnitZ()),
      1.0 - 1e-9);
  EXPECT_NEAR(axes[0].dot(axes[1]), 0.0, 1e-9);
}

// A slab turned about z: its axes turn with it (to the grid's resolution).
TEST(PrincipalAxes, TurnedSlabFollowsItsShape) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.rotate(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()));
  const auto axes = PrincipalAxes(BoxMesh(Eigen::Vector3d(0.24, 0.12, 0.04), pose));
  const Eigen::Matrix3d r = pose.rotation();
  EXPECT_GT(Alignment(axes[2], r.col(0)), 0.99);
  EXPECT_GT(Alignment(axes[1], r.col(1)), 0.99);
  EXPECT_GT(Alignment(axes[0], Eigen::Vector3d::UnitZ()), 0.99);
}

// A cube: every axis is principal; the world axes are returned.
TEST(PrincipalAxes, CubeUsesTheWorldAxes) {
  const auto axes = PrincipalAxes(BoxMesh(Eigen::Vector3d(0.2, 0.2, 0.2),
                                          Eigen::Isometry3d(Eigen::Translation3d(-0.5, 0, 0.3))));
  for (int axis = 0; axis < 3; ++axis) {
    const Eigen::Vector3d world = Eigen::Vector3d::Unit(axis);
    double best = 0.0;
    for (const Eigen::Vector3d& a : axes) best = std::max(best, Alignment(a, world));
    EXPECT_GT(best, 1.0 - 1e-9);
  }
}

}  // namespace
}  // namespace softid::diagnosis
