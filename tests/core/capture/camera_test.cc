#include "core/capture/camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace softid::capture {
namespace {

PinholeCamera MakeCamera() {
  PinholeCamera camera;
  camera.name = "cam";
  camera.width = 640;
  camera.height = 480;
  camera.fx = 525.0;
  camera.fy = 520.0;
  camera.cx = 319.5;
  camera.cy = 239.5;
  camera.X_WC = LookAt(Eigen::Vector3d(1.5, -2.0, 0.8), Eigen::Vector3d(0.1, 0.2, 0.3));
  return camera;
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// LookAt gives OpenCV axes: z towards the target, y (image down) towards -up, x to the right.
TEST(LookAt, GivesOpenCvAxes) {
  const Eigen::Isometry3d X_WC =
      LookAt(Eigen::Vector3d(2, 0, 0), Eigen::Vector3d(0, 0, 0), Eigen::Vector3d::UnitZ());
  const Eigen::Matrix3d R_WC = X_WC.linear();
  EXPECT_TRUE(R_WC.col(2).isApprox(Eigen::Vector3d(-1, 0, 0), 1e-12));
  EXPECT_TRUE(R_WC.col(1).isApprox(Eigen::Vector3d(0, 0, -1), 1e-12));
  // Looking along -x with z up, the right-hand side of the image is +y.
  EXPECT_TRUE(R_WC.col(0).isApprox(Eigen::Vector3d(0, 1, 0), 1e-12));
  EXPECT_NEAR(R_WC.determinant(), 1.0, 1e-12);
  EXPECT_TRUE(X_WC.translation().isApprox(Eigen::Vector3d(2, 0, 0)));
}

// LookAt rejects a view direction parallel to up and a target at the eye.
TEST(LookAt, RejectsDegenerateInput) {
  EXPECT_THROW(LookAt(Eigen::Vector3d(0, 0, 2), Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()),
               std::invalid_argument);
  EXPECT_THROW(LookAt(Eigen::Vector3d::Ones(), Eigen::Vector3d::Ones()), std::invalid_argument);
}

// The LookAt target projects onto the principal point.
TEST(PinholeCamera, TargetProjectsToPrincipalPoint) {
  const PinholeCamera camera = MakeCamera();
  const auto uv = camera.Project(Eigen::Vector3d(0.1, 0.2, 0.3));
  ASSERT_TRUE(uv.has_value());
  EXPECT_NEAR(uv->x(), camera.cx, 1e-9);
  EXPECT_NEAR(uv->y(), camera.cy, 1e-9);
}

// Project then Unproject with the point's depth returns the point; Unproject then Project returns
// the pixel.
TEST(PinholeCamera, ProjectUnprojectRoundTrip) {
  const PinholeCamera camera = MakeCamera();
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d p_W = 0.5 * Eigen::Vector3d::Random();
    const double depth = camera.Depth(p_W);
    ASSERT_GT(depth, 0.0);
    const auto uv = camera.Project(p_W);
    ASSERT_TRUE(uv.has_value());
    EXPECT_TRUE(camera.Unproject(uv->x(), uv->y(), depth).isApprox(p_W, 1e-12));

    const double u = 640.0 * (i % 7) / 7.0, v = 480.0 * (i % 5) / 5.0, z = 0.5 + 0.1 * i;
    const Eigen::Vector3d q_W = camera.Unproject(u, v, z);
    EXPECT_NEAR(camera.Depth(q_W), z, 1e-12);
    const auto uv2 = camera.Project(q_W);
    ASSERT_TRUE(uv2.has_value());
    EXPECT_NEAR(uv2->x(), u, 1e-9);
    EXPECT_NEAR(uv2->y(), v, 1e-9);
  }
}

// A pixel's ray goes through ((col - cx) / fx, (row - cy) / fy, 1) in the camera frame.
TEST(PinholeCamera, RayDirectionThroughPixelCentre) {
  const PinholeCamera camera = MakeCamera();
  EXPECT_TRUE(camera.RayDirection_C(10, 20).isApprox(
      Eigen::Vector3d((10 - 319.5) / 525.0, (20 - 239.5) / 520.0, 1.0), 1e-15));
  EXPECT_TRUE(camera.RayDirection_C(camera.cx, camera.cy).isApprox(Eigen::Vector3d::UnitZ()));
}

// Points behind the camera do not project.
TEST(PinholeCamera, PointBehindDoesNotProject) {
  const PinholeCamera camera = MakeCamera();
  const Eigen::Vector3d behind_W = camera.X_WC * Eigen::Vector3d(0.1, 0.1, -1.0);
  EXPECT_FALSE(camera.Project(behind_W).has_value());
  EXPECT_NEAR(camera.Depth(behind_W), -1.0, 1e-12);
}

// Validate names the offending field and value.
TEST(PinholeCamera, ValidateNamesFieldAndValue) {
  EXPECT_TRUE(MakeCamera().Validate().ok());
  PinholeCamera camera = MakeCamera();
  camera.fx = -1;
  Status status = camera.Validate("cameras[0].");
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(), "cameras[0].fx = -1: must be positive and finite");
  camera = MakeCamera();
  camera.fy = std::numeric_limits<double>::infinity();
  EXPECT_EQ(camera.Validate().message(), "fy = inf: must be positive and finite");
  camera = MakeCamera();
  camera.width = 0;
  EXPECT_EQ(camera.Validate().message(), "width = 0: must be a positive integer");
  camera = MakeCamera();
  camera.cy = 480.0;
  status = camera.Validate();
  EXPECT_TRUE(Contains(status.message(), "cy = 480")) << status.message();
  camera = MakeCamera();
  camera.X_WC.linear() *= 1.01;
  status = camera.Validate();
  EXPECT_TRUE(Contains(status.message(), "X_WC")) << status.message();
  EXPECT_TRUE(Contains(status.message(), "orthonormal")) << status.message();
}

}  // namespace
}  // namespace softid::capture
