#include "core/capture/depth_noise.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

namespace softid::capture {
namespace {

// A 200 x 200 image: left half at z_left, right half at z_right [m], one row without data.
DepthImage TwoDepthImage(float z_left, float z_right) {
  DepthImage image = DepthImage::Zeros(200, 200);
  for (int row = 1; row < 200; ++row) {
    for (int col = 0; col < 200; ++col) image.at(col, row) = col < 100 ? z_left : z_right;
  }
  return image;
}

struct Moments {
  double mean = 0.0;
  double std = 0.0;
};

// Mean and standard deviation of (noisy - clean) over pixels of `clean` equal to z.
Moments ResidualMoments(const DepthImage& clean, const DepthImage& noisy, float z) {
  double sum = 0.0, sum_squares = 0.0;
  int n = 0;
  for (size_t i = 0; i < clean.depth.size(); ++i) {
    if (clean.depth[i] != z) continue;
    const double r = double{noisy.depth[i]} - clean.depth[i];
    sum += r;
    sum_squares += r * r;
    ++n;
  }
  const double mean = sum / n;
  return {mean, std::sqrt(sum_squares / n - mean * mean)};
}

// Residuals have mean ~0 and standard deviation a + b z^2 within 5 % at two depths.
TEST(DepthNoise, GaussianStatisticsFollowSigmaModel) {
  DepthNoiseOptions options;
  options.sigma_constant = 0.002;
  options.sigma_quadratic = 0.003;
  options.seed = 7;
  const DepthImage clean = TwoDepthImage(1.0f, 3.0f);
  DepthImage noisy = clean;
  ApplyDepthNoise(options, 0, 0, &noisy);
  for (const float z : {1.0f, 3.0f}) {
    const double sigma = options.sigma_constant + options.sigma_quadratic * z * z;
    const Moments m = ResidualMoments(clean, noisy, z);
    EXPECT_NEAR(m.mean, 0.0, 4.0 * sigma / std::sqrt(19900.0)) << "z = " << z;
    EXPECT_NEAR(m.std, sigma, 0.05 * sigma) << "z = " << z;
  }
  for (int col = 0; col < 200; ++col) EXPECT_EQ(noisy.at(col, 0), 0.0f);  // no data stays 0
}

// Each valid pixel drops out with the given probability (fraction within 1 %).
TEST(DepthNoise, DropoutFraction) {
  DepthNoiseOptions options;
  options.dropout_probability = 0.2;
  options.seed = 3;
  const DepthImage clean = TwoDepthImage(1.0f, 2.0f);
  DepthImage noisy = clean;
  ApplyDepthNoise(options, 4, 1, &noisy);
  const double fraction =
      1.0 - static_cast<double>(noisy.NumValid()) / static_cast<double>(clean.NumValid());
  EXPECT_NEAR(fraction, 0.2, 0.01);
  // Without Gaussian noise the surviving pixels are unchanged.
  for (size_t i = 0; i < clean.depth.size(); ++i) {
    if (noisy.depth[i] != 0.0f) {
      EXPECT_EQ(noisy.depth[i], clean.depth[i]);
    }
  }
}

// The noise is a function of (seed, frame, camera): equal inputs give equal images, changing any
// of the three changes the image.
TEST(DepthNoise, DeterministicPerSeedFrameCamera) {
  DepthNoiseOptions options;
  options.sigma_constant = 0.001;
  options.dropout_probability = 0.1;
  options.seed = 11;
  const DepthImage clean = TwoDepthImage(1.0f, 2.0f);
  const auto noisy = [&](uint64_t seed, int frame, int camera) {
    DepthNoiseOptions o = options;
    o.seed = seed;
    DepthImage image = clean;
    ApplyDepthNoise(o, frame, camera, &image);
    return image.depth;
  };
  EXPECT_EQ(noisy(11, 2, 1), noisy(11, 2, 1));
  EXPECT_NE(noisy(11, 2, 1), noisy(12, 2, 1));
  EXPECT_NE(noisy(11, 2, 1), noisy(11, 3, 1));
  EXPECT_NE(noisy(11, 2, 1), noisy(11, 2, 0));
  EXPECT_NE(noisy(11, 2, 1), clean.depth);
}

// Validate rejects negative or non-finite sigmas and a dropout probability outside [0, 1).
TEST(DepthNoiseOptions, ValidateRejectsBadValues) {
  EXPECT_TRUE(DepthNoiseOptions{}.Validate().ok());
  DepthNoiseOptions options;
  options.sigma_constant = -0.001;
  EXPECT_NE(options.Validate().message().find("sigma_constant = -0.001"), std::string::npos);
  options = {};
  options.sigma_quadratic = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(options.Validate().message().find("sigma_quadratic"), std::string::npos);
  options = {};
  options.dropout_probability = 1.0;
  EXPECT_NE(options.Validate().message().find("dropout_probability = 1"), std::string::npos);
  DepthImage image = TwoDepthImage(1.0f, 1.0f);
  EXPECT_THROW(ApplyDepthNoise(options, 0, 0, &image), std::invalid_argument);
}

}  // namespace
}  // namespace softid::capture
