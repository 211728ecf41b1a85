// Where the scanned mesh sits in the first frame: its pose found from the object's observed points
// alone, from any starting pose (FPFH features matched by RANSAC), then refined by point-to-plane
// ICP against the visible part (Open3D). A station's scanner and camera share no frame, so no
// initial guess is assumed.
#pragma once

#include <Eigen/Geometry>
#include <memory>
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

// The mesh's surface as ICP's target, sampled once (with its triangles' normals) for a pose
// refined frame after frame. Move-only.
class MeshSurface {
 public:
  // `points` samples spread uniformly over the area of mesh_S (metres, its own frame S), > 0.
  MeshSurface(const geometry::TriangleMesh& mesh_S, int points);
  ~MeshSurface();
  MeshSurface(MeshSurface&&) noexcept;
  MeshSurface& operator=(MeshSurface&&) noexcept;

  struct Samples;
  const Samples& samples() const { return *samples_; }

 private:
  std::unique_ptr<Samples> samples_;
};

// The pose of a moving mesh in a later frame, from a prediction X_CS: point-to-plane ICP of
// `observed_C` onto `surface`, first pairing points within `capture_m` (the prediction's error:
// the object's motion between frames), then within 3 noise sigmas as RefineMeshPose. Fewer than 30
// points: InvalidArgument. The overlap is reported, not checked.
Result<MeshRegistration> TrackMeshPose(const MeshSurface& surface,
                                       const std::vector<Eigen::Vector3d>& observed_C,
                                       const Eigen::Isometry3d& X_CS, double capture_m,
                                       double noise_sigma_m);

}  // namespace softid::ingest
