#include "core/ingest/contact_sheet.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/capture/depth_renderer.h"
#include "core/common/json_fields.h"

namespace softid::ingest {
namespace {

const cv::Vec3b kObjectBgr(40, 40, 230);
const cv::Vec3b kFloorBgr(60, 190, 60);
const cv::Scalar kOutlineBgr(0, 230, 255);

// The frame's depth in grey over [near_m, far_m] (near bright, no data black), the floor's pixels
// tinted green and the object's red.
cv::Mat Tile(const capture::DepthImage& image, const std::vector<int>& object_pixels,
             const FloorPlane& floor, const capture::PixelRays& rays, float near_m, float far_m) {
  cv::Mat tile(image.height, image.width, CV_8UC3);
  for (int row = 0; row < image.height; ++row) {
    for (int col = 0; col < image.width; ++col) {
      const float d = image.at(col, row);
      const uint8_t grey =
          d > 0.0f ? static_cast<uint8_t>(
                         std::clamp(40.0f + 215.0f * (far_m - d) / (far_m - near_m), 40.0f, 255.0f))
                   : 0;
      cv::Vec3b pixel(grey, grey, grey);
      const Eigen::Vector2d& xy = rays.at(col, row);
      if (d > 0.0f && std::abs(floor.SignedDistance(d * Eigen::Vector3d(xy.x(), xy.y(), 1.0))) <=
                          floor.threshold_m) {
        pixel = 0.5 * pixel + 0.5 * kFloorBgr;
      }
      tile.at<cv::Vec3b>(row, col) = pixel;
    }
  }
  for (const int pixel : object_pixels) {
    cv::Vec3b& value = tile.at<cv::Vec3b>(pixel / image.width, pixel % image.width);
    value = 0.35 * value + 0.65 * kObjectBgr;
  }
  return tile;
}

// The outline of the registered mesh as camera 0 sees it (through its lens).
std::vector<std::vector<cv::Point>> MeshOutline(const recording::RecordingCamera& camera,
                                                const IngestReport& report,
                                                const geometry::TriangleMesh& mesh_S,
                                                const capture::PixelRays& rays) {
  geometry::TriangleMesh mesh_C = mesh_S;
  for (Eigen::Vector3d& v : mesh_C.vertices) v = report.registration.X_CS * v;
  capture::PinholeCamera at_origin = camera.camera;
  at_origin.X_WC = Eigen::Isometry3d::Identity();
  const capture::DepthImage rendered = capture::DepthRenderer().Render(mesh_C, at_origin, rays);
  cv::Mat silhouette(rendered.height, rendered.width, CV_8UC1, cv::Scalar(0));
  for (int i = 0; i < static_cast<int>(rendered.depth.size()); ++i) {
    if (rendered.depth[i] > 0.0f)
      silhouette.at<uint8_t>(i / rendered.width, i % rendered.width) = 255;
  }
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(silhouette, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  return contours;
}

std::vector<int> ShownFrames(int frames, int max_frames) {
  const int shown = std::min(frames, max_frames);
  std::vector<int> indices;
  for (int i = 0; i < shown; ++i) {
    indices.push_back(
        shown == 1 ? 0 : static_cast<int>(std::lround(i * (frames - 1.0) / (shown - 1.0))));
  }
  return indices;
}

}  // namespace

Status ContactSheetOptions::Validate() const {
  if (max_frames < 1) return json::Invalid("max_frames", max_frames, "must be at least 1");
  if (columns < 1) return json::Invalid("columns", columns, "must be at least 1");
  if (min_tile_px < 1) return json::Invalid("min_tile_px", min_tile_px, "must be at least 1");
  return Status::Ok();
}

Status WriteContactSheet(const std::filesystem::path& path, const recording::Recording& rec,
                         const IngestReport& report, const geometry::TriangleMesh& mesh_S,
                         const capture::PixelRays& rays, const ContactSheetOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (rec.NumCameras() == 0 || report.cameras.empty() || rec.cameras[0].frames.empty()) {
    return Status::InvalidArgument("contact sheet " + path.string() + ": no frames");
  }
  const recording::RecordingCamera& camera = rec.cameras[0];
  const std::vector<int> shown =
      ShownFrames(static_cast<int>(camera.frames.size()), options.max_frames);
  std::vector<capture::DepthImage> images;
  float near_m = std::numeric_limits<float>::max(), far_m = 0.0f;
  for (const int k : shown) {
    SOFTID_ASSIGN_OR_RETURN(capture::DepthImage image, recording::LoadRecordingFrame(rec, 0, k));
    for (const float d : image.depth) {
      if (d > 0.0f) near_m = std::min(near_m, d), far_m = std::max(far_m, d);
    }
    images.push_back(std::move(image));
  }
  if (!(far_m > near_m)) far_m = near_m + 1e-3f;
  const int width = camera.camera.width, height = camera.camera.height;
  const int scale = std::max(1, (options.min_tile_px + width - 1) / width);
  const int columns = std::min<int>(options.columns, static_cast<int>(shown.size()));
  const int rows = (static_cast<int>(shown.size()) + columns - 1) / columns;
  const int tile_w = width * scale, tile_h = height * scale, gap = 4;
  cv::Mat sheet(rows * (tile_h + gap) + gap, columns * (tile_w + gap) + gap, CV_8UC3,
                cv::Scalar(40, 40, 40));
  for (size_t i = 0; i < shown.size(); ++i) {
    cv::Mat tile;
    cv::resize(Tile(images[i], report.cameras[0].object_masks[shown[i]], report.floor_C, rays,
                    near_m, far_m),
               tile, cv::Size(tile_w, tile_h), 0, 0, cv::INTER_NEAREST);
    if (i == 0) {
      std::vector<std::vector<cv::Point>> outline = MeshOutline(camera, report, mesh_S, rays);
      for (auto& contour : outline) {
        for (cv::Point& p : contour) p = p * scale + cv::Point(scale / 2, scale / 2);
      }
      cv::drawContours(tile, outline, -1, kOutlineBgr, std::max(1, scale / 2));
    }
    const int x = gap + static_cast<int>(i % columns) * (tile_w + gap);
    const int y = gap + static_cast<int>(i / columns) * (tile_h + gap);
    tile.copyTo(sheet(cv::Rect(x, y, tile_w, tile_h)));
    cv::putText(sheet, std::to_string(shown[i]), cv::Point(x + 4, y + 16), cv::FONT_HERSHEY_SIMPLEX,
                0.45, cv::Scalar(255, 255, 255), 1);
  }
  if (!cv::imwrite(path.string(), sheet)) {
    return Status::IoError("cannot write contact sheet " + path.string());
  }
  return Status::Ok();
}

}  // namespace softid::ingest
