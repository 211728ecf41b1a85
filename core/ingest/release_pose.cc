#include "core/ingest/release_pose.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <string>

#include "core/capture/depth_renderer.h"
#include "core/ingest/mesh_registration.h"

namespace softid::ingest {
namespace {

// A mesh in the wrong unit cannot match: compare its size with the spread of the object's points.
Status CheckMeshScale(const geometry::TriangleMesh& mesh, const std::vector<Eigen::Vector3d>& seen,
                      const std::string& camera_name) {
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3d& p : seen) box.extend(p);
  const double seen_m = box.diagonal().norm();
  const double mesh_m = mesh.Bounds().diagonal().norm();
  if (seen_m > 1.5 * mesh_m || seen_m < 0.05 * mesh_m) {
    return Status::FailedPrecondition(fmt::format(
        "ingest: camera \"{}\" frame 0: the object's points span {:.3g} m but the mesh's diagonal "
        "is {:.3g} m: the mesh's size cannot match (is mesh_unit right?)",
        camera_name, seen_m, mesh_m));
  }
  return Status::Ok();
}

// The object's points at the release in camera 0's frame: camera 0's first frame, and the first
// frame of every other camera that saw the release at the same time (a synchronised rig sees the
// object from more sides, which pins its pose; an unsynchronised camera's first frame may show it
// already moved).
std::vector<Eigen::Vector3d> ReleasePoints(const recording::Recording& rec,
                                           const IngestOptions& options,
                                           const std::vector<CameraView>& views,
                                           std::vector<int>* cameras) {
  std::vector<Eigen::Vector3d> points = views[0].release_points_C;
  cameras->assign(1, 0);
  const double t0 = rec.cameras[0].frames[0].time_s;
  const Eigen::Isometry3d X_C0W = views[0].X_WC.inverse();
  for (int c = 1; c < rec.NumCameras(); ++c) {
    if (std::abs(rec.cameras[c].frames[0].time_s - t0) > options.same_time_s) continue;
    const Eigen::Isometry3d X_C0C = X_C0W * views[c].X_WC;
    cameras->push_back(c);
    for (const Eigen::Vector3d& p_C : views[c].release_points_C) points.push_back(X_C0C * p_C);
  }
  return points;
}

// The first frames' points inside the silhouette of the mesh posed at X_C0S (in camera 0's frame)
// whose depths lie within window_m of the posed mesh's, in camera 0's frame. The window is the
// same on both sides of the mesh, so it keeps a reading whichever way noise moved it.
Result<std::vector<Eigen::Vector3d>> SilhouettePoints(const recording::Recording& rec,
                                                      const geometry::TriangleMesh& mesh_S,
                                                      const std::vector<CameraView>& views,
                                                      const std::vector<int>& cameras,
                                                      const Eigen::Isometry3d& X_C0S,
                                                      double window_m) {
  geometry::TriangleMesh mesh_W = mesh_S;
  const Eigen::Isometry3d X_WS = views[0].X_WC * X_C0S;
  for (Eigen::Vector3d& v : mesh_W.vertices) v = X_WS * v;
  const capture::DepthRenderer renderer;
  const Eigen::Isometry3d X_C0W = views[0].X_WC.inverse();
  std::vector<Eigen::Vector3d> points;
  for (const int c : cameras) {
    SOFTID_ASSIGN_OR_RETURN(const capture::DepthImage frame,
                            recording::LoadRecordingFrame(rec, c, 0));
    capture::PinholeCamera camera = rec.cameras[c].camera;
    camera.X_WC = views[c].X_WC;
    const capture::DepthImage posed = renderer.Render(mesh_W, camera, views[c].rays);
    cv::Mat1b inside(frame.height, frame.width, uint8_t{0});
    for (int p = 0; p < static_cast<int>(posed.depth.size()); ++p) {
      if (posed.depth[p] > 0.0f) inside(p / frame.width, p % frame.width) = 1;
    }
    const Eigen::Isometry3d X_C0C = X_C0W * views[c].X_WC;
    for (int p = 0; p < static_cast<int>(frame.depth.size()); ++p) {
      const float z = frame.depth[p];
      if (!inside(p / frame.width, p % frame.width) || z <= 0.0f) continue;
      // What stands in front of the object (clutter) or shows through a scan's hole is not it.
      if (std::abs(z - posed.depth[p]) > window_m) continue;
      const Eigen::Vector2d& xy = views[c].rays.xy[p];
      points.push_back(X_C0C * (z * Eigen::Vector3d(xy.x(), xy.y(), 1.0)));
    }
  }
  return points;
}

}  // namespace

Status PoseMeshAtRelease(const recording::Recording& rec, const geometry::TriangleMesh& mesh_S,
                         const IngestOptions& options, const std::vector<CameraView>& views,
                         IngestReport* report) {
  const std::vector<Eigen::Vector3d>& first = views[0].release_points_C;
  SOFTID_RETURN_IF_ERROR(CheckMeshScale(mesh_S, first, rec.cameras[0].camera.name));
  MeshRegistrationOptions registration = options.registration;
  const std::vector<float>& sigmas = views[0].scene.sigma_m;
  if (std::any_of(sigmas.begin(), sigmas.end(), [](float sigma) { return sigma > 0.0f; }))
    registration.noise_sigma_m = MedianSigma(views[0].scene);
  std::vector<int> cameras;
  const std::vector<Eigen::Vector3d> points = ReleasePoints(rec, options, views, &cameras);
  report->registration_cameras.clear();
  for (const int c : cameras) report->registration_cameras.push_back(rec.cameras[c].camera.name);
  report->registration_points = static_cast<int>(points.size());
  Result<MeshRegistration> found = RegisterMesh(mesh_S, points, registration);
  if (!found.ok()) {
    // A mesh of another object, or in another unit than declared, matches no pose.
    return Status(found.status().code(),
                  fmt::format("ingest: camera \"{}\" frame 0: {} (is the mesh this object, and "
                              "is mesh_unit right?)",
                              rec.cameras[0].camera.name, found.status().message()));
  }
  // Refined on the silhouettes' points; kept when it still converges.
  SOFTID_ASSIGN_OR_RETURN(
      const std::vector<Eigen::Vector3d> inside,
      SilhouettePoints(rec, mesh_S, views, cameras, found->X_CS, found->max_distance_m));
  if (inside.size() >= 30) {
    Result<MeshRegistration> refined = RefineMeshPose(mesh_S, inside, found->X_CS, registration);
    if (refined.ok() && refined->overlap >= registration.min_overlap) {
      refined->hypothesis = found->hypothesis;
      found = std::move(refined);
    }
  }
  report->registration = *found;
  report->X_WS = views[0].X_WC * found->X_CS;
  return Status::Ok();
}

}  // namespace softid::ingest
