// Depth images in memory and as 16-bit single-channel PNG files.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <vector>

#include "core/capture/camera.h"
#include "core/common/status.h"

namespace softid::capture {

// A depth image: depth along the camera z axis [m] per pixel, row-major (index row * width + col);
// 0 means no data.
struct DepthImage {
  int width = 0;
  int height = 0;
  std::vector<float> depth;  // [m] along camera z, 0 = no data, row-major, size width * height

  // An image of the given size with no data (all zeros).
  static DepthImage Zeros(int width, int height);

  float at(int col, int row) const { return depth[static_cast<size_t>(row) * width + col]; }
  float& at(int col, int row) { return depth[static_cast<size_t>(row) * width + col]; }
  // Number of pixels with data (depth > 0).
  int NumValid() const;
};

// Largest value a 16-bit PNG pixel can hold.
inline constexpr int kMaxDepthPngValue = 65535;

// Writes `image` as a 16-bit single-channel PNG holding round(depth / depth_scale) per pixel
// (depth_scale [m per unit] > 0, e.g. 0.001 for millimetres). Pixels with depth 0 are written as 0.
// InvalidArgument naming the path when depth_scale is not positive and finite, the image size does
// not match its data, or a pixel cannot be stored: negative or non-finite depth, a positive depth
// that would round to 0 (below depth_scale / 2) or one above 65535 * depth_scale; IoError when the
// file cannot be written.
Status WriteDepthPng(const std::filesystem::path& path, const DepthImage& image,
                     double depth_scale);

// Reads a 16-bit single-channel PNG written as above: depth = value * depth_scale [m]. NotFound
// when the file does not exist; InvalidArgument naming the path when it is not a PNG, cannot be
// decoded (corrupt or truncated), is not 16-bit single-channel (e.g. 8-bit or RGB) or is not
// expected_width x expected_height pixels.
Result<DepthImage> ReadDepthPng(const std::filesystem::path& path, double depth_scale,
                                int expected_width, int expected_height);

// Checks only the PNG header (signature and IHDR chunk) of a depth PNG: 16-bit greyscale of the
// expected size. Same errors as ReadDepthPng except that a corrupt body goes undetected; much
// faster than decoding.
Status CheckDepthPngHeader(const std::filesystem::path& path, int expected_width,
                           int expected_height);

// World points p_W [m] of every pixel with data, unprojected through the pixel centre, in
// row-major pixel order. The image must have the camera's size (else std::invalid_argument).
std::vector<Eigen::Vector3d> DepthToWorldPoints(const DepthImage& image,
                                                const PinholeCamera& camera);

}  // namespace softid::capture
