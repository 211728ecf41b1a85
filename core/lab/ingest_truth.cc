#include "core/lab/ingest_truth.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <opencv2/imgcodecs.hpp>

#include "core/geometry/mesh_distance.h"
#include "core/scenes/raw_recording_synthesis.h"

namespace softid::lab {
namespace {

constexpr double kDegreesPerRadian = 180.0 / std::numbers::pi;

Eigen::Isometry3d Pose(const nlohmann::json& numbers) {
  Eigen::Matrix4d m;
  for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = numbers.at(i).get<double>();
  return Eigen::Isometry3d(m);
}

double IoU(const std::vector<int>& found, const cv::Mat& truth) {
  std::vector<uint8_t> mine(truth.total(), 0);
  for (const int p : found) mine[p] = 1;
  int both = 0, either = 0;
  for (size_t p = 0; p < mine.size(); ++p) {
    const bool t = truth.data[p] > 0;
    both += mine[p] && t;
    either += mine[p] || t;
  }
  return either == 0 ? 1.0 : static_cast<double>(both) / either;
}

void CompareMasks(const std::filesystem::path& dir, const ingest::IngestReport& report,
                  IngestAccuracy* out) {
  for (const ingest::CameraIngest& camera : report.cameras) {
    for (size_t k = 0; k < camera.object_masks.size(); ++k) {
      const std::filesystem::path file =
          dir / scenes::kTrueMasksFolder / camera.name / fmt::format("{:06d}.png", k);
      if (!std::filesystem::exists(file)) return;
      const cv::Mat mask = cv::imread(file.string(), cv::IMREAD_GRAYSCALE);
      const double iou = mask.empty() ? 0.0 : IoU(camera.object_masks[k], mask);
      if (iou < out->worst_iou) {
        out->worst_iou = iou;
        out->worst_iou_camera = camera.name;
        out->worst_iou_frame = static_cast<int>(k);
      }
    }
  }
}

// The symmetry of the mesh nearest `turn` (a rigid map of the mesh's frame): ICP of the mesh onto
// itself from `turn`. A body that `turn` maps onto itself within 0.1 % of its size (a torus turned
// about its axis, a pillow flipped) is the same body in either pose, so the pose found is judged
// against the true pose composed with that symmetry; otherwise the identity.
Eigen::Isometry3d NearestSymmetry(const geometry::TriangleMesh& mesh,
                                  const geometry::MeshDistance& rest,
                                  const Eigen::Isometry3d& turn) {
  const int n = static_cast<int>(mesh.vertices.size());
  Eigen::Matrix3Xd from(3, n), to(3, n);
  for (int i = 0; i < n; ++i) from.col(i) = mesh.vertices[i];
  Eigen::Isometry3d symmetry = turn;
  double rms = 0.0;
  for (int iteration = 0; iteration < 30; ++iteration) {
    rms = 0.0;
    for (int i = 0; i < n; ++i) {
      const geometry::ClosestPoint closest = rest.Closest(symmetry * mesh.vertices[i]);
      to.col(i) = closest.point;
      rms += closest.distance * closest.distance;
    }
    symmetry.matrix() = Eigen::umeyama(from, to, false);
  }
  const double size = mesh.Bounds().sizes().norm();
  return std::sqrt(rms / n) <= 1e-3 * size ? symmetry : Eigen::Isometry3d::Identity();
}

Status ComparePose(const recording::Recording& rec, const ingest::IngestReport& report,
                   const Eigen::Isometry3d& X_CS_true, IngestAccuracy* out) {
  SOFTID_ASSIGN_OR_RETURN(const geometry::TriangleMesh mesh, recording::LoadRecordingMesh(rec));
  SOFTID_ASSIGN_OR_RETURN(const geometry::MeshDistance rest, geometry::MeshDistance::Create(mesh));
  const Eigen::Isometry3d& X_CS_found = report.registration.X_CS;
  const Eigen::Isometry3d X_CS_equivalent =
      X_CS_true * NearestSymmetry(mesh, rest, X_CS_true.inverse() * X_CS_found);
  double surface = 0.0, vertex = 0.0;
  for (const Eigen::Vector3d& v : mesh.vertices) {
    // The distance to the truly posed surface, measured in the mesh's frame.
    surface += std::pow(rest.Distance(X_CS_true.inverse() * (X_CS_found * v)), 2);
    vertex += (X_CS_found * v - X_CS_equivalent * v).squaredNorm();
  }
  out->surface_rms_m = std::sqrt(surface / mesh.vertices.size());
  out->vertex_rms_m = std::sqrt(vertex / mesh.vertices.size());
  const Eigen::AngleAxisd turn(X_CS_equivalent.linear().transpose() * X_CS_found.linear());
  out->rotation_deg = std::abs(turn.angle()) * kDegreesPerRadian;
  return Status::Ok();
}

}  // namespace

Result<IngestAccuracy> CompareIngestWithTruth(const std::filesystem::path& dir,
                                              const recording::Recording& rec,
                                              const ingest::IngestReport& report) {
  const std::filesystem::path truth_file = dir / "truth.json";
  nlohmann::json truth;
  try {
    std::ifstream(truth_file) >> truth;
  } catch (const nlohmann::json::exception& error) {
    return Status::InvalidArgument(truth_file.string() + ": " + error.what());
  }
  if (!truth.contains("raw")) {
    return Status::InvalidArgument(truth_file.string() +
                                   ": no \"raw\" block (not a raw recording)");
  }
  IngestAccuracy out;
  try {
    const nlohmann::json& raw = truth["raw"];
    const Eigen::Isometry3d X_WC = Pose(raw["cameras"][0]["world_from_camera"]);
    const Eigen::Vector3d n_W(raw["floor"]["normal"][0], raw["floor"]["normal"][1],
                              raw["floor"]["normal"][2]);
    const Eigen::Vector3d n_C = X_WC.linear().transpose() * n_W;
    const double offset_C = raw["floor"]["offset"].get<double>() - n_W.dot(X_WC.translation());
    out.floor_angle_deg =
        std::acos(std::clamp(n_C.dot(report.floor_C.normal_C), -1.0, 1.0)) * kDegreesPerRadian;
    out.floor_offset_m = std::abs(offset_C - report.floor_C.offset_m);
    SOFTID_RETURN_IF_ERROR(
        ComparePose(rec, report, X_WC.inverse() * Pose(raw["world_from_scanner"]), &out));
  } catch (const nlohmann::json::exception& error) {
    return Status::InvalidArgument(truth_file.string() + ": \"raw\": " + error.what());
  }
  CompareMasks(dir, report, &out);
  return out;
}

}  // namespace softid::lab
