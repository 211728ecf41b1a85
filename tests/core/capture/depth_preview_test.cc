#include "core/capture/depth_preview.h"

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "tests/core/capture/test_temp_dir.h"

namespace softid::capture {
namespace {

// The contact sheet shows the chosen number of frames in a grid, upscaled, with no-data black.
TEST(DepthPreview, WritesAGridOfFrames) {
  std::vector<DepthImage> frames;
  for (int f = 0; f < 30; ++f) {
    DepthImage image = DepthImage::Zeros(20, 10);
    for (int c = 0; c < 10; ++c) image.at(c + f % 10, 5) = 1.0f + 0.01f * c;
    frames.push_back(image);
  }
  const testing::TempDir dir;
  const auto path = dir.path() / "preview.png";
  DepthPreviewOptions options;
  options.max_frames = 6;
  options.columns = 3;
  options.min_tile_px = 40;
  ASSERT_TRUE(WriteDepthPreview(path, frames, options).ok());
  const cv::Mat sheet = cv::imread(path.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(sheet.empty());
  EXPECT_EQ(sheet.cols, 3 * (40 + 4) + 4);  // 20 px frames upscaled x2
  EXPECT_EQ(sheet.rows, 2 * (20 + 4) + 4);
  // A no-data pixel of the first tile is black; an object pixel is not.
  EXPECT_EQ(sheet.at<cv::Vec3b>(4 + 2, 4 + 38), cv::Vec3b(0, 0, 0));
  EXPECT_NE(sheet.at<cv::Vec3b>(4 + 2 * 5 + 1, 4 + 1), cv::Vec3b(0, 0, 0));
}

// No frames is an error naming the path.
TEST(DepthPreview, RejectsNoFrames) {
  const Status s = WriteDepthPreview("/tmp/nothing.png", {});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("/tmp/nothing.png"), std::string::npos);
}

// An empty first frame (no pixels) is an error naming its size, not a division by zero.
TEST(DepthPreview, RejectsAnEmptyFrame) {
  const Status s = WriteDepthPreview("/tmp/empty.png", {DepthImage{}});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame 0 is 0 x 0 pixels"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace softid::capture
