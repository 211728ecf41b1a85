#include "core/capture/depth_image.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <system_error>

#include "core/common/check.h"

namespace softid::capture {

DepthImage DepthImage::Zeros(int width, int height) {
  SOFTID_THROW_UNLESS(width >= 0 && height >= 0, "DepthImage::Zeros: negative size");
  DepthImage image;
  image.width = width;
  image.height = height;
  image.depth.assign(static_cast<size_t>(width) * height, 0.0f);
  return image;
}

int DepthImage::NumValid() const {
  return static_cast<int>(std::count_if(depth.begin(), depth.end(), [](float d) { return d > 0; }));
}

namespace {

constexpr std::array<uint8_t, 8> kPngSignature = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
// Signature (8) + IHDR length (4) + "IHDR" (4) + width, height (8) + bit depth, colour type (2).
constexpr size_t kPngHeaderBytes = 26;

uint32_t ReadBigEndian32(const uint8_t* bytes) {
  return (uint32_t{bytes[0]} << 24) | (uint32_t{bytes[1]} << 16) | (uint32_t{bytes[2]} << 8) |
         uint32_t{bytes[3]};
}

const char* PngColourTypeName(int colour_type) {
  switch (colour_type) {
    case 0: return "greyscale";
    case 2: return "RGB";
    case 3: return "palette";
    case 4: return "greyscale+alpha";
    case 6: return "RGBA";
  }
  return "unknown colour type";
}

// Checks the PNG signature and IHDR chunk at the start of `bytes` (size n): 16-bit greyscale of
// the expected size.
Status CheckPngHeaderBytes(const std::filesystem::path& path, const uint8_t* bytes, size_t n,
                           int expected_width, int expected_height) {
  if (n < kPngHeaderBytes || !std::equal(kPngSignature.begin(), kPngSignature.end(), bytes) ||
      !std::equal(bytes + 12, bytes + 16, "IHDR")) {
    return Status::InvalidArgument(
        fmt::format("{}: not a PNG file (bad signature or header)", path.string()));
  }
  const uint32_t width = ReadBigEndian32(bytes + 16);
  const uint32_t height = ReadBigEndian32(bytes + 20);
  const int bit_depth = bytes[24];
  const int colour_type = bytes[25];
  if (bit_depth != 16 || colour_type != 0) {
    return Status::InvalidArgument(fmt::format(
        "{}: PNG is {}-bit {} ({} channel(s)): depth frames must be 16-bit single-channel "
        "(greyscale)",
        path.string(), bit_depth, PngColourTypeName(colour_type),
        colour_type == 0   ? 1
        : colour_type == 4 ? 2
        : colour_type == 6 ? 4
                           : 3));
  }
  if (width != static_cast<uint32_t>(expected_width) ||
      height != static_cast<uint32_t>(expected_height)) {
    return Status::InvalidArgument(
        fmt::format("{}: image size {}x{}: expected {}x{} (width x height)", path.string(), width,
                    height, expected_width, expected_height));
  }
  return Status::Ok();
}

Status CheckExpectedSize(const std::filesystem::path& path, int expected_width,
                         int expected_height) {
  if (expected_width > 0 && expected_height > 0) return Status::Ok();
  return Status::InvalidArgument(fmt::format("{}: expected size {}x{}: must be positive",
                                             path.string(), expected_width, expected_height));
}

Status CheckFileExists(const std::filesystem::path& path) {
  std::error_code error;
  const auto status = std::filesystem::status(path, error);
  if (!std::filesystem::exists(status)) {
    return Status::NotFound(fmt::format("{}: file not found", path.string()));
  }
  if (!std::filesystem::is_regular_file(status)) {
    return Status::InvalidArgument(fmt::format("{}: not a regular file", path.string()));
  }
  return Status::Ok();
}

Result<std::vector<uint8_t>> ReadFileBytes(const std::filesystem::path& path, size_t max_bytes) {
  SOFTID_RETURN_IF_ERROR(CheckFileExists(path));
  std::ifstream file(path, std::ios::binary);
  if (!file) return Status::InvalidArgument(fmt::format("{}: cannot open file", path.string()));
  std::vector<uint8_t> bytes;
  if (max_bytes == SIZE_MAX) {
    bytes.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
  } else {
    bytes.resize(max_bytes);
    file.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(max_bytes));
    bytes.resize(static_cast<size_t>(file.gcount()));
  }
  if (file.bad()) return Status::InvalidArgument(fmt::format("{}: read error", path.string()));
  return bytes;
}

}  // namespace

Status WriteDepthPng(const std::filesystem::path& path, const DepthImage& image,
                     double depth_scale) {
  if (!(std::isfinite(depth_scale) && depth_scale > 0.0)) {
    return Status::InvalidArgument(fmt::format("{}: depth_scale = {}: must be positive and finite",
                                               path.string(), depth_scale));
  }
  if (image.width <= 0 || image.height <= 0 ||
      image.depth.size() != static_cast<size_t>(image.width) * image.height) {
    return Status::InvalidArgument(
        fmt::format("{}: image is {}x{} with {} depth values: size must be positive and match",
                    path.string(), image.width, image.height, image.depth.size()));
  }
  cv::Mat mat(image.height, image.width, CV_16UC1);
  for (int row = 0; row < image.height; ++row) {
    auto* out = mat.ptr<uint16_t>(row);
    for (int col = 0; col < image.width; ++col) {
      const double depth = image.at(col, row);
      if (depth == 0.0) {
        out[col] = 0;
        continue;
      }
      const double value = std::round(depth / depth_scale);
      if (!(std::isfinite(depth) && depth > 0.0 && value >= 1.0 && value <= kMaxDepthPngValue)) {
        return Status::InvalidArgument(fmt::format(
            "{}: pixel (col {}, row {}) depth = {} m: cannot be stored with depth_scale = {} "
            "(representable: [{}, {}] m, or 0 for no data)",
            path.string(), col, row, depth, depth_scale, 0.5 * depth_scale,
            kMaxDepthPngValue * depth_scale));
      }
      out[col] = static_cast<uint16_t>(value);
    }
  }
  std::vector<uint8_t> encoded;
  try {
    if (!cv::imencode(".png", mat, encoded)) {
      return Status::Internal(fmt::format("{}: PNG encoding failed", path.string()));
    }
  } catch (const cv::Exception& e) {
    return Status::Internal(fmt::format("{}: PNG encoding failed: {}", path.string(), e.what()));
  }
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  file.write(reinterpret_cast<const char*>(encoded.data()),
             static_cast<std::streamsize>(encoded.size()));
  file.close();
  if (!file) return Status::IoError(fmt::format("{}: cannot write file", path.string()));
  return Status::Ok();
}

Status CheckDepthPngHeader(const std::filesystem::path& path, int expected_width,
                           int expected_height) {
  SOFTID_RETURN_IF_ERROR(CheckExpectedSize(path, expected_width, expected_height));
  SOFTID_ASSIGN_OR_RETURN(const std::vector<uint8_t> bytes, ReadFileBytes(path, kPngHeaderBytes));
  return CheckPngHeaderBytes(path, bytes.data(), bytes.size(), expected_width, expected_height);
}

Result<DepthImage> ReadDepthPng(const std::filesystem::path& path, double depth_scale,
                                int expected_width, int expected_height) {
  if (!(std::isfinite(depth_scale) && depth_scale > 0.0)) {
    return Status::InvalidArgument(fmt::format("{}: depth_scale = {}: must be positive and finite",
                                               path.string(), depth_scale));
  }
  SOFTID_RETURN_IF_ERROR(CheckExpectedSize(path, expected_width, expected_height));
  SOFTID_ASSIGN_OR_RETURN(const std::vector<uint8_t> bytes, ReadFileBytes(path, SIZE_MAX));
  SOFTID_RETURN_IF_ERROR(
      CheckPngHeaderBytes(path, bytes.data(), bytes.size(), expected_width, expected_height));
  cv::Mat mat;
  try {
    const cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8UC1,
                         const_cast<uint8_t*>(bytes.data()));
    mat = cv::imdecode(buffer, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return Status::InvalidArgument(
        fmt::format("{}: cannot decode PNG (corrupt or truncated): {}", path.string(), e.what()));
  }
  if (mat.empty()) {
    return Status::InvalidArgument(
        fmt::format("{}: cannot decode PNG (corrupt or truncated)", path.string()));
  }
  if (mat.type() != CV_16UC1) {
    return Status::InvalidArgument(
        fmt::format("{}: decoded image has {} channel(s) of {} bytes: depth frames must be 16-bit "
                    "single-channel",
                    path.string(), mat.channels(), mat.elemSize1()));
  }
  if (mat.cols != expected_width || mat.rows != expected_height) {
    return Status::InvalidArgument(fmt::format("{}: image size {}x{}: expected {}x{}",
                                               path.string(), mat.cols, mat.rows, expected_width,
                                               expected_height));
  }
  DepthImage image = DepthImage::Zeros(mat.cols, mat.rows);
  for (int row = 0; row < mat.rows; ++row) {
    const auto* in = mat.ptr<uint16_t>(row);
    for (int col = 0; col < mat.cols; ++col) {
      image.at(col, row) = static_cast<float>(in[col] * depth_scale);
    }
  }
  return image;
}

std::vector<Eigen::Vector3d> DepthToWorldPoints(const DepthImage& image,
                                                const PinholeCamera& camera) {
  SOFTID_THROW_UNLESS(image.width == camera.width && image.height == camera.height &&
                          image.depth.size() == static_cast<size_t>(image.width) * image.height,
                      "DepthToWorldPoints: image size must match the camera");
  std::vector<Eigen::Vector3d> points_W;
  points_W.reserve(static_cast<size_t>(image.NumValid()));
  for (int row = 0; row < image.height; ++row) {
    for (int col = 0; col < image.width; ++col) {
      const float depth = image.at(col, row);
      if (depth > 0.0f) points_W.push_back(camera.Unproject(col, row, depth));
    }
  }
  return points_W;
}

}  // namespace softid::capture
