#include "core/capture/depth_image.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <stdexcept>
#include <string>

#include "tests/core/capture/test_temp_dir.h"

namespace softid::capture {
namespace {

using testing::TempDir;

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

DepthImage RandomDepthImage(int width, int height, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> depth(0.3f, 5.0f);
  std::bernoulli_distribution empty(0.3);
  DepthImage image = DepthImage::Zeros(width, height);
  for (float& d : image.depth) d = empty(rng) ? 0.0f : depth(rng);
  return image;
}

// Writing and reading a PNG reproduces every depth within depth_scale / 2; no-data stays 0.
TEST(DepthPng, RoundTripWithinHalfDepthScale) {
  const TempDir dir;
  const double depth_scale = 0.0005;
  const DepthImage image = RandomDepthImage(37, 23, 1);
  const auto path = dir.path() / "depth.png";
  ASSERT_TRUE(WriteDepthPng(path, image, depth_scale).ok());
  const Result<DepthImage> read = ReadDepthPng(path, depth_scale, 37, 23);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  ASSERT_EQ(read->width, 37);
  ASSERT_EQ(read->height, 23);
  ASSERT_EQ(read->depth.size(), image.depth.size());
  double max_error = 0.0;
  for (size_t i = 0; i < image.depth.size(); ++i) {
    EXPECT_EQ(read->depth[i] == 0.0f, image.depth[i] == 0.0f) << i;
    max_error = std::max(max_error, std::abs(double{read->depth[i]} - image.depth[i]));
  }
  EXPECT_LE(max_error, depth_scale / 2 + 1e-6);
  EXPECT_GT(max_error, 0.0);  // quantisation did happen
  EXPECT_EQ(read->NumValid(), image.NumValid());
}

// Depths a 16-bit PNG cannot hold are rejected with the path named, and nothing is written.
TEST(DepthPng, WriteRejectsUnrepresentableDepth) {
  const TempDir dir;
  DepthImage image = DepthImage::Zeros(4, 3);
  image.at(1, 2) = 70.0f;  // > 65535 * 0.001 m
  const auto path = dir.path() / "far.png";
  Status status = WriteDepthPng(path, image, 0.001);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(status.message(), path.string())) << status.message();
  EXPECT_TRUE(Contains(status.message(), "depth = 70")) << status.message();
  EXPECT_FALSE(std::filesystem::exists(path));
  image.at(1, 2) = -0.5f;
  EXPECT_EQ(WriteDepthPng(path, image, 0.001).code(), StatusCode::kInvalidArgument);
  image.at(1, 2) = 1.0f;
  EXPECT_EQ(WriteDepthPng(path, image, 0.0).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(WriteDepthPng(path, image, 0.001).ok());
}

// A missing file is NotFound; an 8-bit, RGB, wrongly sized, corrupt or truncated PNG is
// InvalidArgument naming the path.
TEST(DepthPng, ReadRejectsBadFiles) {
  const TempDir dir;
  EXPECT_EQ(ReadDepthPng(dir.path() / "missing.png", 0.001, 8, 6).status().code(),
            StatusCode::kNotFound);

  const auto eight_bit = dir.path() / "eight.png";
  ASSERT_TRUE(cv::imwrite(eight_bit.string(), cv::Mat(6, 8, CV_8UC1, cv::Scalar(7))));
  Status status = ReadDepthPng(eight_bit, 0.001, 8, 6).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(status.message(), eight_bit.string())) << status.message();
  EXPECT_TRUE(Contains(status.message(), "8-bit")) << status.message();

  const auto rgb = dir.path() / "rgb.png";
  ASSERT_TRUE(cv::imwrite(rgb.string(), cv::Mat(6, 8, CV_16UC3, cv::Scalar(7, 8, 9))));
  status = ReadDepthPng(rgb, 0.001, 8, 6).status();
  EXPECT_TRUE(Contains(status.message(), "RGB")) << status.message();

  const auto good = dir.path() / "good.png";
  ASSERT_TRUE(WriteDepthPng(good, RandomDepthImage(8, 6, 2), 0.001).ok());
  status = ReadDepthPng(good, 0.001, 9, 6).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(status.message(), "8x6")) << status.message();
  EXPECT_TRUE(CheckDepthPngHeader(good, 8, 6).ok());
  EXPECT_FALSE(CheckDepthPngHeader(eight_bit, 8, 6).ok());

  const auto garbage = dir.path() / "garbage.png";
  std::ofstream(garbage) << "this is not a png";
  status = ReadDepthPng(garbage, 0.001, 8, 6).status();
  EXPECT_TRUE(Contains(status.message(), "not a PNG")) << status.message();

  const auto truncated = dir.path() / "truncated.png";
  ASSERT_TRUE(WriteDepthPng(truncated, RandomDepthImage(64, 48, 3), 0.001).ok());
  std::filesystem::resize_file(truncated, std::filesystem::file_size(truncated) / 2);
  EXPECT_TRUE(CheckDepthPngHeader(truncated, 64, 48).ok());  // the header alone looks fine
  status = ReadDepthPng(truncated, 0.001, 64, 48).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(status.message(), "cannot decode")) << status.message();
}

// Unprojection goes through pixel centres and keeps only pixels with data.
TEST(DepthToWorldPoints, UnprojectsValidPixelsThroughCentres) {
  PinholeCamera camera;
  camera.width = 5;
  camera.height = 4;
  camera.fx = camera.fy = 10.0;
  camera.cx = 2.0;
  camera.cy = 1.5;
  camera.X_WC.translation() = Eigen::Vector3d(1, 2, 3);
  DepthImage image = DepthImage::Zeros(5, 4);
  image.at(4, 1) = 2.0f;
  image.at(0, 3) = 0.5f;
  const auto points_W = DepthToWorldPoints(image, camera);
  ASSERT_EQ(points_W.size(), 2u);
  EXPECT_TRUE(points_W[0].isApprox(Eigen::Vector3d(1 + 2.0 * 0.2, 2 + 2.0 * -0.05, 3 + 2.0)));
  EXPECT_TRUE(points_W[1].isApprox(Eigen::Vector3d(1 + 0.5 * -0.2, 2 + 0.5 * 0.15, 3 + 0.5)));
  EXPECT_THROW(DepthToWorldPoints(DepthImage::Zeros(4, 4), camera), std::invalid_argument);
}

}  // namespace
}  // namespace softid::capture
