#include "core/capture/depth_preview.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/json_fields.h"

namespace softid::capture {
namespace {

// Indices of `shown` frames spread evenly from the first to the last.
std::vector<int> EvenlySpacedFrames(const std::vector<DepthImage>& frames, int shown) {
  std::vector<int> indices;
  for (int i = 0; i < shown; ++i) {
    indices.push_back(shown == 1 ? 0
                                 : static_cast<int>(std::lround(double(i) * (frames.size() - 1) /
                                                                double(shown - 1))));
  }
  return indices;
}

// Depth range the colour map spans [m]; never empty.
struct DepthRange {
  float lo, hi;
};

DepthRange ValidDepthRange(const std::vector<DepthImage>& frames, const std::vector<int>& indices) {
  float lo = std::numeric_limits<float>::max(), hi = 0.0f;
  for (int index : indices) {
    for (float d : frames[index].depth) {
      if (d > 0.0f) {
        lo = std::min(lo, d);
        hi = std::max(hi, d);
      }
    }
  }
  if (!(hi > lo)) hi = lo + 1e-3f;
  return {lo, hi};
}

// The frame colour-mapped over `range` (no data black), upscaled to tile_w x tile_h pixels.
cv::Mat ColourTile(const DepthImage& frame, DepthRange range, int tile_w, int tile_h) {
  const int width = frame.width, height = frame.height;
  const float lo = range.lo, hi = range.hi;
  cv::Mat gray(height, width, CV_8UC1);
  cv::Mat valid(height, width, CV_8UC1);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      const float d = frame.at(c, r);
      valid.at<uint8_t>(r, c) = d > 0.0f ? 255 : 0;
      // Near is bright.
      gray.at<uint8_t>(r, c) =
          d > 0.0f ? static_cast<uint8_t>(std::clamp(255.0f * (hi - d) / (hi - lo), 0.0f, 255.0f))
                   : 0;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(gray, colour, cv::COLORMAP_TURBO);
  colour.setTo(cv::Scalar(0, 0, 0), valid == 0);
  cv::Mat tile;
  cv::resize(colour, tile, cv::Size(tile_w, tile_h), 0, 0, cv::INTER_NEAREST);
  return tile;
}

}  // namespace

Status DepthPreviewOptions::Validate() const {
  if (max_frames < 1) return json::Invalid("max_frames", max_frames, "must be at least 1");
  if (columns < 1) return json::Invalid("columns", columns, "must be at least 1");
  if (min_tile_px < 1) return json::Invalid("min_tile_px", min_tile_px, "must be at least 1");
  return Status::Ok();
}

Status WriteDepthPreview(const std::filesystem::path& path, const std::vector<DepthImage>& frames,
                         const DepthPreviewOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (frames.empty()) return Status::InvalidArgument("preview of " + path.string() + ": no frames");
  const int width = frames[0].width, height = frames[0].height;
  if (width <= 0 || height <= 0) {
    return Status::InvalidArgument("preview of " + path.string() + ": frame 0 is " +
                                   std::to_string(width) + " x " + std::to_string(height) +
                                   " pixels");
  }
  const int shown = std::min<int>(options.max_frames, static_cast<int>(frames.size()));
  const std::vector<int> indices = EvenlySpacedFrames(frames, shown);
  const DepthRange range = ValidDepthRange(frames, indices);
  const int scale = std::max(1, (options.min_tile_px + width - 1) / width);
  const int columns = std::min(options.columns, shown);
  const int rows = (shown + columns - 1) / columns;
  const int tile_w = width * scale, tile_h = height * scale, gap = 4;
  cv::Mat sheet(rows * (tile_h + gap) + gap, columns * (tile_w + gap) + gap, CV_8UC3,
                cv::Scalar(40, 40, 40));
  for (int i = 0; i < shown; ++i) {
    const DepthImage& frame = frames[indices[i]];
    if (frame.width != width || frame.height != height) {
      return Status::InvalidArgument("preview of " + path.string() + ": frame " +
                                     std::to_string(indices[i]) + " has another size");
    }
    const cv::Mat tile = ColourTile(frame, range, tile_w, tile_h);
    const int x = gap + (i % columns) * (tile_w + gap);
    const int y = gap + (i / columns) * (tile_h + gap);
    tile.copyTo(sheet(cv::Rect(x, y, tile_w, tile_h)));
    cv::putText(sheet, std::to_string(indices[i]), cv::Point(x + 4, y + 16),
                cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(255, 255, 255), 1);
  }
  if (!cv::imwrite(path.string(), sheet)) {
    return Status::IoError("cannot write preview " + path.string());
  }
  return Status::Ok();
}

}  // namespace softid::capture
