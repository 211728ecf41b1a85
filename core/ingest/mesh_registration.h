// Where the scanned mesh sits in the first frame: its pose found from the object's observed points
// alone, from any starting pose (FPFH features matched by RANSAC), then refined by point-to-plane
// ICP against the visible part (Open3D). A station's scanner and camera share no frame, so no
// initial guess is assumed.
#pragma once

#include <Eigen/Geometry>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::ingest {

struct MeshRegistrationOptions {
  // Feature scale: the voxel of the downsampled clouds is the mesh's bounding-box diagonal over
  // this [1]. Features span 5 voxels, normals 2.
  double voxels_per_diagonal = 30.0;
  // Global hypotheses: RANSAC attempts with different draws, and a grid of this many orientations
  // (20 axes times 10 turns for 200); each is refined by ICP and the best overlap wins.
  int attempts = 2;
  int rotations = 200;
  int ransac_iterations = 100000;
  // Depth noise of the observed points [m]: the final ICP pairs points within 3 sigma (at least a
  // quarter voxel).
  double noise_sigma_m = 0.002;
  // A registration whose overlap (share of observed points within the final distance of the
  // mesh) is lower than this did not converge.
  double min_overlap = 0.8;
  unsigned seed = 1;
  // Threads refining hypotheses side by side; 0 = one per core.
  int threads = 0;  // >= 0

  Status Validate() const;
};

struct MeshRegistration {
  // Pose of the mesh's (scanner) frame S in the observing camera's frame C: p_C = X_CS * p_S.
  Eigen::Isometry3d X_CS = Eigen::Isometry3d::Identity();
  double overlap = 0.0;  // share of observed points within max_distance_m of the posed mesh
  double rms_m = 0.0;    // RMS distance of those points to the mesh's surface
  double max_distance_m = 0.0;
  int hypothesis = 0;  // rank (by coarse overlap) of the hypothesis that won
};

// Registers `mesh_S` (metres, any frame) to `observed_C` (the object's points in the camera frame
// [m], one side of it). InvalidArgument for an empty mesh or fewer than 30 points;
// FailedPrecondition naming the overlap and RMS reached when no attempt reaches min_overlap.
Result<MeshRegistration> RegisterMesh(const geometry::TriangleMesh& mesh_S,
                                      const std::vector<Eigen::Vector3d>& observed_C,
                                      const MeshRegistrationOptions& options = {});

// The final ICP alone, from the pose X_CS: for points chosen without regard to their depths (the
// pixels inside the posed mesh's silhouette), which a depth threshold's choice is not (near the
// threshold it keeps the readings noise moved towards the camera). Errors as RegisterMesh's
// argument checks; the overlap is reported, not checked.
Result<MeshRegistration> RefineMeshPose(const geometry::TriangleMesh& mesh_S,
                                        const std::vector<Eigen::Vector3d>& observed_C,
                                        const Eigen::Isometry3d& X_CS,
                                        const MeshRegistrationOptions& options = {});

}  // namespace softid::ingest
