// The depth noise measured on frame 0 against the rest mesh, before any fit.
#include "core/inverse/rest_frame_noise.h"

#include <gtest/gtest.h>

#include "core/capture/depth_image.h"
#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

using testing::MakeSmallCapture;
using testing::SmallCapture;

double EstimatedSigma(const SmallCapture& capture) {
  Result<RestFrameNoise> noise = EstimateRestFrameNoise(capture.capture, capture.mesh);
  EXPECT_TRUE(noise.ok()) << noise.status().ToString();
  if (!noise.ok()) return -1.0;
  EXPECT_GT(noise->points, 100);
  EXPECT_GE(noise->sigma_m, noise->quantisation_sigma_m);
  return noise->sigma_m;
}

// A noise-free capture shows only the depth quantum; added noise shows, and twice the noise is
// measured about twice as large. The distance to the surface is the depth error times the cosine
// between ray and normal, so the estimate lies below the depth sigma but not far below.
TEST(RestFrameNoise, FollowsTheSensorNoise) {
  const SmallCapture clean = MakeSmallCapture("ball-bounce", 0.05, 2, 8);
  const SmallCapture noisy = MakeSmallCapture("ball-bounce", 0.05, 2, 8, 2e-3);
  const SmallCapture noisier = MakeSmallCapture("ball-bounce", 0.05, 2, 8, 4e-3);
  ASSERT_TRUE(clean.ok && noisy.ok && noisier.ok) << clean.error << noisy.error << noisier.error;
  const double quantum = DepthQuantisationSigma(clean.capture);
  const double sigma_clean = EstimatedSigma(clean);
  const double sigma_noisy = EstimatedSigma(noisy);
  const double sigma_noisier = EstimatedSigma(noisier);
  EXPECT_LT(sigma_clean, 4.0 * quantum);
  EXPECT_GT(sigma_noisy, 0.8e-3);
  EXPECT_LT(sigma_noisy, 2.2e-3);
  EXPECT_NEAR(sigma_noisier / sigma_noisy, 2.0, 0.4);
}

TEST(RestFrameNoise, RefusesACaptureWithoutFrameZeroPoints) {
  SmallCapture capture = MakeSmallCapture("ball-bounce", 0.05, 1, 8);
  ASSERT_TRUE(capture.ok) << capture.error;
  // Frame 0 without data: the object is out of view.
  const capture::CameraRecording& camera = capture.capture.cameras[0];
  ASSERT_TRUE(
      capture::WriteDepthPng(capture.capture.directory / camera.frames[0],
                             capture::DepthImage::Zeros(camera.camera.width, camera.camera.height),
                             camera.depth_scale)
          .ok());
  const Result<RestFrameNoise> noise = EstimateRestFrameNoise(capture.capture, capture.mesh);
  ASSERT_FALSE(noise.ok());
  EXPECT_NE(noise.status().message().find("frame 0"), std::string::npos)
      << noise.status().ToString();
}

}  // namespace
}  // namespace softid::inverse
