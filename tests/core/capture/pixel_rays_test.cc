#include "core/capture/pixel_rays.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/capture/depth_renderer.h"
#include "core/geometry/primitives.h"

namespace softid::capture {
namespace {

PinholeCamera MakeCamera() {
  PinholeCamera camera;
  camera.name = "cam";
  camera.width = 160;
  camera.height = 120;
  camera.fx = 150.0;
  camera.fy = 152.0;
  camera.cx = 79.0;
  camera.cy = 61.5;
  return camera;
}

// A wide depth lens: strong barrel distortion, some tangential.
const DistortionCoefficients kWideLens = {-0.28, 0.09, 0.0012, -0.0008, -0.012};

// Without distortion the rays are the pinhole's.
TEST(PixelRays, PinholeWithoutDistortion) {
  const PinholeCamera camera = MakeCamera();
  const Result<PixelRays> rays = ComputePixelRays(camera, {});
  ASSERT_TRUE(rays.ok()) << rays.status().ToString();
  for (int row = 0; row < camera.height; row += 11) {
    for (int col = 0; col < camera.width; col += 13) {
      EXPECT_EQ(rays->at(col, row), camera.RayDirection_C(col, row).head<2>());
    }
  }
}

// Each pixel's ray projects back through OpenCV's forward model onto that pixel's centre.
TEST(PixelRays, InvertTheDistortionModel) {
  const PinholeCamera camera = MakeCamera();
  for (const DistortionCoefficients& lens :
       {kWideLens, DistortionCoefficients{-0.1, 0.02, 0.0, 0.0},
        DistortionCoefficients{-0.2, 0.05, 0.001, 0.001, 0.0, 0.01, 0.0, 0.0}}) {
    const Result<PixelRays> rays = ComputePixelRays(camera, lens);
    ASSERT_TRUE(rays.ok()) << rays.status().ToString();
    double worst = 0.0;
    for (int row = 0; row < camera.height; ++row) {
      for (int col = 0; col < camera.width; ++col) {
        const Eigen::Vector2d& xy = rays->at(col, row);
        const Eigen::Vector2d pixel =
            ProjectDistorted(camera, lens, 1.7 * Eigen::Vector3d(xy.x(), xy.y(), 1.0));
        worst = std::max(worst, (pixel - Eigen::Vector2d(col, row)).norm());
      }
    }
    EXPECT_LT(worst, 1e-6) << "pixels";
  }
}

// A camera with a real lens records depth along z of the true surface: a sphere rendered through
// the lens and unprojected along the same rays lies on the sphere; the corner pixels differ from a
// pinhole's by many pixels.
TEST(PixelRays, RenderedThroughTheLensUnprojectOntoTheSurface) {
  PinholeCamera camera = MakeCamera();
  camera.X_WC = LookAt(Eigen::Vector3d(0.0, -0.5, 0.1), Eigen::Vector3d::Zero());
  const geometry::TriangleMesh sphere = geometry::MakeSphere(0.25, 5);
  const Result<PixelRays> rays = ComputePixelRays(camera, kWideLens);
  ASSERT_TRUE(rays.ok());
  const DepthImage image = DepthRenderer().Render(sphere, camera, *rays);
  int valid = 0;
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      const float z = image.at(col, row);
      if (z == 0.0f) continue;
      ++valid;
      const Eigen::Vector3d p_C =
          z * Eigen::Vector3d(rays->at(col, row).x(), rays->at(col, row).y(), 1.0);
      EXPECT_NEAR((camera.X_WC * p_C).norm(), 0.25, 1e-3);
    }
  }
  EXPECT_GT(valid, 3000);
  const Eigen::Vector2d corner = rays->at(0, 0);
  const Eigen::Vector2d pinhole = camera.RayDirection_C(0, 0).head<2>();
  EXPECT_GT(camera.fx * (corner - pinhole).norm(), 5.0);
}

TEST(PixelRays, RejectsBadCoefficients) {
  const PinholeCamera camera = MakeCamera();
  const Result<PixelRays> three = ComputePixelRays(camera, {0.1, 0.2, 0.3});
  ASSERT_FALSE(three.ok());
  EXPECT_NE(three.status().message().find("distortion has 3 coefficients"), std::string::npos)
      << three.status().message();
  const Result<PixelRays> nan = ComputePixelRays(camera, {0.1, NAN, 0.0, 0.0});
  ASSERT_FALSE(nan.ok());
  EXPECT_NE(nan.status().message().find("distortion[1]"), std::string::npos);
}

// k1 = -3 turns the radial polynomial back at a third of the focal length from the centre, well
// inside the image: no ray maps to the corner pixels, and the coefficients are refused with the
// pixel the inversion missed (coefficients in another order or for another camera do this).
TEST(PixelRays, RejectsALensThatFoldsTheImage) {
  const PinholeCamera camera = MakeCamera();
  const Result<PixelRays> folded = ComputePixelRays(camera, {-3.0, 0.0, 0.0, 0.0});
  ASSERT_FALSE(folded.ok());
  EXPECT_EQ(folded.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(folded.status().message().find("folds the image"), std::string::npos)
      << folded.status().message();
  EXPECT_NE(folded.status().message().find("distortion = [-3, 0, 0, 0]"), std::string::npos)
      << folded.status().message();
}

}  // namespace
}  // namespace softid::capture
