#include "core/ingest/mesh_registration.h"

#include <fmt/format.h>
#include <open3d/geometry/KDTreeFlann.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/pipelines/registration/CorrespondenceChecker.h>
#include <open3d/pipelines/registration/Feature.h>
#include <open3d/pipelines/registration/Registration.h>
#include <open3d/utility/Random.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>

#include "core/common/for_each_index.h"
#include "core/ingest/openmp_threads.h"

namespace softid::ingest {
namespace {

namespace o3d = open3d;
namespace reg = open3d::pipelines::registration;

// Points sampled uniformly over the mesh's area, with the triangles' normals.
std::shared_ptr<o3d::geometry::PointCloud> SampleSurface(const geometry::TriangleMesh& mesh,
                                                         int count) {
  o3d::geometry::TriangleMesh o3d_mesh(mesh.vertices, mesh.triangles);
  o3d_mesh.ComputeTriangleNormals();
  return o3d_mesh.SamplePointsUniformly(count, /*use_triangle_normal=*/true);
}

struct Features {
  std::shared_ptr<o3d::geometry::PointCloud> cloud;
  std::shared_ptr<reg::Feature> fpfh;
};

Features DownsampleWithFeatures(const o3d::geometry::PointCloud& cloud, double voxel) {
  Features out;
  out.cloud = cloud.VoxelDownSample(voxel);
  out.cloud->EstimateNormals(o3d::geometry::KDTreeSearchParamHybrid(2 * voxel, 30));
  out.fpfh =
      reg::ComputeFPFHFeature(*out.cloud, o3d::geometry::KDTreeSearchParamHybrid(5 * voxel, 100));
  return out;
}

// Starting poses (observed -> model) for a grid of orientations: Fibonacci-sphere axes times
// in-plane turns; the model's centroid is placed behind the observed points' centroid, along the
// viewing ray, by half the model's mean radius (one side of a body is seen, its centre lies
// behind).
std::vector<Eigen::Matrix4d> RotationGridStarts(const geometry::TriangleMesh& mesh_S,
                                                const std::vector<Eigen::Vector3d>& observed_C,
                                                int rotations) {
  Eigen::Vector3d model_centre = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& v : mesh_S.vertices) model_centre += v;
  model_centre /= static_cast<double>(mesh_S.vertices.size());
  double radius = 0.0;
  for (const Eigen::Vector3d& v : mesh_S.vertices) radius += (v - model_centre).norm();
  radius /= static_cast<double>(mesh_S.vertices.size());
  Eigen::Vector3d observed_centre = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : observed_C) observed_centre += p;
  observed_centre /= static_cast<double>(observed_C.size());
  const Eigen::Vector3d centre_C = observed_centre + 0.5 * radius * observed_centre.normalized();
  constexpr int kTurns = 10;
  const int axes = std::max(1, rotations / kTurns);
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  std::vector<Eigen::Matrix4d> starts;
  for (int a = 0; a < axes; ++a) {
    const double z = 1.0 - 2.0 * (a + 0.5) / axes;
    const double r = std::sqrt(1.0 - z * z);
    const Eigen::Vector3d axis(r * std::cos(golden * a), r * std::sin(golden * a), z);
    const Eigen::Matrix3d tilt =
        Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), axis).toRotationMatrix();
    for (int t = 0; t < kTurns; ++t) {
      // R_CS: model -> camera; the start maps observed -> model, its inverse.
      const Eigen::Matrix3d R_CS =
          tilt * Eigen::AngleAxisd(2.0 * std::numbers::pi * t / kTurns, Eigen::Vector3d::UnitZ())
                     .toRotationMatrix();
      Eigen::Isometry3d X_CS = Eigen::Isometry3d::Identity();
      X_CS.linear() = R_CS;
      X_CS.translation() = centre_C - R_CS * model_centre;
      starts.push_back(X_CS.inverse().matrix());
    }
  }
  return starts;
}

// At most this many observed points in the final ICP.
constexpr size_t kFinalPoints = 20000;

// The checks RegisterMesh and RefineMeshPose share.
Status CheckInputs(const geometry::TriangleMesh& mesh_S,
                   const std::vector<Eigen::Vector3d>& observed_C,
                   const MeshRegistrationOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (mesh_S.vertices.empty() || mesh_S.triangles.empty()) {
    return Status::InvalidArgument("registration: the mesh is empty");
  }
  if (observed_C.size() < 30) {
    return Status::InvalidArgument(fmt::format(
        "registration: {} observed points of the object (at least 30)", observed_C.size()));
  }
  return Status::Ok();
}

// Lengths of one registration: the features' voxel and the final ICP's pairing distance.
struct RegistrationScale {
  double voxel_m = 0.0;
  double fine_distance_m = 0.0;

  RegistrationScale(const geometry::TriangleMesh& mesh_S, const MeshRegistrationOptions& options)
      : voxel_m(mesh_S.Bounds().diagonal().norm() / options.voxels_per_diagonal),
        fine_distance_m(std::max(3.0 * options.noise_sigma_m, 0.25 * voxel_m)) {}
};

// Stops once an iteration changes the inlier share by less than 1e-6 and the RMS by less than a
// micrometre (Open3D compares absolute changes): far below the pose's noise. Tighter limits ran
// all 60 iterations every time, a third of a 100-frame ingest, for no change in the pose beyond
// a few hundredths of a millimetre (docs/benchmarks.md).
reg::RegistrationResult FineIcp(const o3d::geometry::PointCloud& observed,
                                const o3d::geometry::PointCloud& model, double distance_m,
                                const Eigen::Matrix4d& start) {
  return reg::RegistrationICP(observed, model, distance_m, start,
                              reg::TransformationEstimationPointToPlane(),
                              reg::ICPConvergenceCriteria(1e-6, 1e-6, 60));
}

// Every observed point, or kFinalPoints of them taken evenly: the pose's noise falls as one over
// the root of the count, and is a few hundredths of a millimetre there.
std::shared_ptr<o3d::geometry::PointCloud> FinalPoints(const o3d::geometry::PointCloud& observed) {
  const size_t every = (observed.points_.size() + kFinalPoints - 1) / kFinalPoints;
  return every <= 1 ? std::make_shared<o3d::geometry::PointCloud>(observed)
                    : observed.UniformDownSample(every);
}

MeshRegistration FromIcp(const reg::RegistrationResult& icp, double distance_m) {
  MeshRegistration out;
  out.X_CS = Eigen::Isometry3d(icp.transformation_).inverse();
  out.overlap = icp.fitness_;
  out.rms_m = icp.inlier_rmse_;
  out.max_distance_m = distance_m;
  return out;
}

// Hypotheses (observed -> model): a grid of rotations with the model set behind the observed
// side, and RANSAC on FPFH features (features of one side of an object match its whole surface
// poorly, so RANSAC alone fails on some views).
std::vector<Eigen::Matrix4d> Hypotheses(const geometry::TriangleMesh& mesh_S,
                                        const std::vector<Eigen::Vector3d>& observed_C,
                                        const Features& observed, const Features& model,
                                        double voxel_m, const MeshRegistrationOptions& options) {
  std::vector<Eigen::Matrix4d> starts = RotationGridStarts(mesh_S, observed_C, options.rotations);
  const reg::CorrespondenceCheckerBasedOnEdgeLength edges(0.9);
  const reg::CorrespondenceCheckerBasedOnDistance distance(1.5 * voxel_m);
  o3d::utility::random::Seed(static_cast<int>(options.seed));
  for (int attempt = 0; attempt < options.attempts; ++attempt) {
    starts.push_back(reg::RegistrationRANSACBasedOnFeatureMatching(
                         *observed.cloud, *model.cloud, *observed.fpfh, *model.fpfh,
                         /*mutual_filter=*/true, 1.5 * voxel_m,
                         reg::TransformationEstimationPointToPoint(false), 3, {edges, distance},
                         reg::RANSACConvergenceCriteria(options.ransac_iterations, 0.999))
                         .transformation_);
  }
  return starts;
}

// At most this many observed points in the coarse ICP that ranks the hypotheses.
constexpr size_t kRankingPoints = 500;

// The best `keep` hypotheses after a coarse ICP on the downsampled clouds, best first. Each ICP
// runs on one thread; results land by index, so the outcome does not depend on the threads.
// Ranking only tells the right basin from the wrong ones, which differ in overlap by far more than
// a share measured on 500 points scatters (+-2 %); the survivors are refined on every point. (Three
// 640 x 480 views give ~1,100 downsampled points: ranking 200 hypotheses on all of them took
// 1.3 s of a 100-frame ingest.)
std::vector<Eigen::Matrix4d> RankHypotheses(const std::vector<Eigen::Matrix4d>& starts,
                                            const Features& observed, const Features& model,
                                            double voxel_m, size_t keep, int workers) {
  const size_t every = (observed.cloud->points_.size() + kRankingPoints - 1) / kRankingPoints;
  const std::shared_ptr<o3d::geometry::PointCloud> ranked =
      every <= 1 ? observed.cloud : observed.cloud->UniformDownSample(every);
  std::vector<std::pair<double, Eigen::Matrix4d>> coarse(starts.size());
  ForEachIndex(starts.size(), workers, [&](size_t i) {
    const reg::RegistrationResult r = reg::RegistrationICP(
        *ranked, *model.cloud, 2.0 * voxel_m, starts[i],
        reg::TransformationEstimationPointToPlane(), reg::ICPConvergenceCriteria(1e-4, 1e-4, 15));
    coarse[i] = {r.fitness_ - r.inlier_rmse_ / (2.0 * voxel_m), r.transformation_};
  });
  keep = std::min(keep, coarse.size());
  std::partial_sort(coarse.begin(), coarse.begin() + keep, coarse.end(),
                    [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<Eigen::Matrix4d> best;
  for (size_t i = 0; i < keep; ++i) best.push_back(coarse[i].second);
  return best;
}

// Index of the refined hypothesis with the most overlap (ties within 0.1 % by the lower RMS).
int Winner(const std::vector<reg::RegistrationResult>& refined) {
  int winner = 0;
  for (size_t i = 1; i < refined.size(); ++i) {
    const reg::RegistrationResult& fine = refined[i];
    const reg::RegistrationResult& best = refined[winner];
    if (fine.fitness_ > best.fitness_ + 1e-3 ||
        (fine.fitness_ > best.fitness_ - 1e-3 && fine.inlier_rmse_ < best.inlier_rmse_)) {
      winner = static_cast<int>(i);
    }
  }
  return winner;
}

}  // namespace

Status MeshRegistrationOptions::Validate() const {
  if (!(voxels_per_diagonal >= 5.0) || !std::isfinite(voxels_per_diagonal)) {
    return Status::InvalidArgument(
        fmt::format("voxels_per_diagonal = {}: must be >= 5", voxels_per_diagonal));
  }
  if (attempts < 0 || ransac_iterations < 1 || rotations < 0 || attempts + rotations < 1) {
    return Status::InvalidArgument(
        fmt::format("attempts = {}, rotations = {}, ransac_iterations = {}: need >= 0, >= 0 (not "
                    "both 0) and >= 1",
                    attempts, rotations, ransac_iterations));
  }
  if (!(noise_sigma_m >= 0.0) || !std::isfinite(noise_sigma_m) ||
      !(min_overlap > 0.0 && min_overlap <= 1.0)) {
    return Status::InvalidArgument(fmt::format(
        "noise_sigma_m = {}, min_overlap = {}: need >= 0 and (0, 1]", noise_sigma_m, min_overlap));
  }
  if (threads < 0) return Status::InvalidArgument(fmt::format("threads = {}: need >= 0", threads));
  return Status::Ok();
}

Result<MeshRegistration> RegisterMesh(const geometry::TriangleMesh& mesh_S,
                                      const std::vector<Eigen::Vector3d>& observed_C,
                                      const MeshRegistrationOptions& options) {
  SOFTID_RETURN_IF_ERROR(CheckInputs(mesh_S, observed_C, options));
  const ScopedOpenMPThreads serial(1);
  const RegistrationScale scale(mesh_S, options);
  const std::shared_ptr<o3d::geometry::PointCloud> model = SampleSurface(mesh_S, 60000);
  const o3d::geometry::PointCloud observed(observed_C);
  const Features model_features = DownsampleWithFeatures(*model, scale.voxel_m);
  const Features observed_features = DownsampleWithFeatures(observed, scale.voxel_m);
  const int workers = options.threads > 0 ? options.threads : CoreCount();
  const std::vector<Eigen::Matrix4d> survivors = RankHypotheses(
      Hypotheses(mesh_S, observed_C, observed_features, model_features, scale.voxel_m, options),
      observed_features, model_features, scale.voxel_m, /*keep=*/6, workers);

  // The survivors are refined on the observed cloud thinned to half a voxel (a 640 x 480 view
  // holds tens of thousands of points, and nearest-neighbour queries of all of them for every
  // hypothesis were most of the ingest's time); the winner is refined on the final points.
  const std::shared_ptr<o3d::geometry::PointCloud> thinned =
      observed.VoxelDownSample(0.5 * scale.voxel_m);
  const auto refine = [&](const o3d::geometry::PointCloud& cloud, const Eigen::Matrix4d& start) {
    const reg::RegistrationResult mid = reg::RegistrationICP(
        cloud, *model, scale.voxel_m, start, reg::TransformationEstimationPointToPlane());
    return FineIcp(cloud, *model, scale.fine_distance_m, mid.transformation_);
  };
  std::vector<reg::RegistrationResult> refined(survivors.size());
  ForEachIndex(survivors.size(), workers,
               [&](size_t i) { refined[i] = refine(*thinned, survivors[i]); });
  const int winner = Winner(refined);
  // The winner has converged on the thinned cloud: only the fine pairing distance is left to run.
  MeshRegistration best = FromIcp(FineIcp(*FinalPoints(observed), *model, scale.fine_distance_m,
                                          refined[winner].transformation_),
                                  scale.fine_distance_m);
  best.hypothesis = winner;
  if (best.overlap < options.min_overlap) {
    return Status::FailedPrecondition(fmt::format(
        "registration of the mesh to the first frame did not converge: {:.0f} % of the {} object "
        "points lie within {:.1f} mm of the posed mesh (needs {:.0f} %), RMS {:.2f} mm",
        100 * best.overlap, observed_C.size(), 1e3 * scale.fine_distance_m,
        100 * options.min_overlap, 1e3 * best.rms_m));
  }
  return best;
}

Result<MeshRegistration> RefineMeshPose(const geometry::TriangleMesh& mesh_S,
                                        const std::vector<Eigen::Vector3d>& observed_C,
                                        const Eigen::Isometry3d& X_CS,
                                        const MeshRegistrationOptions& options) {
  SOFTID_RETURN_IF_ERROR(CheckInputs(mesh_S, observed_C, options));
  const ScopedOpenMPThreads serial(1);
  const RegistrationScale scale(mesh_S, options);
  const std::shared_ptr<o3d::geometry::PointCloud> model = SampleSurface(mesh_S, 60000);
  const o3d::geometry::PointCloud observed(observed_C);
  return FromIcp(
      FineIcp(*FinalPoints(observed), *model, scale.fine_distance_m, X_CS.inverse().matrix()),
      scale.fine_distance_m);
}

// At most this many observed points in a tracked pose: it places a silhouette, to a fraction of
// a pixel, not a registration.
constexpr size_t kTrackingPoints = 500;

struct MeshSurface::Samples {
  std::shared_ptr<o3d::geometry::PointCloud> cloud;
  o3d::geometry::KDTreeFlann tree;
};

MeshSurface::MeshSurface(const geometry::TriangleMesh& mesh_S, int points)
    : samples_(std::make_unique<Samples>()) {
  samples_->cloud = SampleSurface(mesh_S, std::max(1, points));
  samples_->tree.SetGeometry(*samples_->cloud);
}

MeshSurface::~MeshSurface() = default;
MeshSurface::MeshSurface(MeshSurface&&) noexcept = default;
MeshSurface& MeshSurface::operator=(MeshSurface&&) noexcept = default;

namespace {

// Point-to-plane ICP of `observed` onto the surface from T (observed -> model) with pairs within
// distance_m, until an iteration changes the share of paired points by less than 1e-3 and their
// RMS by less than 1 % (the model's samples lie millimetres apart: the RMS jitters by that much
// as a pose slides over them), or 30 iterations; the fitness and RMS at the result. (Judged on
// the residual, not the pose: a torus turns freely about its axis.) Open3D's RegistrationICP
// builds the model's k-d tree on every call: a tracker calls this twice a frame, and the tree of
// 10,000 samples cost more than the iterations.
reg::RegistrationResult IcpOnSurface(const o3d::geometry::PointCloud& observed,
                                     const MeshSurface::Samples& model, double distance_m,
                                     Eigen::Matrix4d T) {
  const reg::TransformationEstimationPointToPlane estimation;
  o3d::geometry::PointCloud moved = observed;
  std::vector<int> index(1);
  std::vector<double> squared(1);
  reg::RegistrationResult result(T);
  for (int iteration = 0; iteration <= 30; ++iteration) {
    moved.points_ = observed.points_;
    moved.Transform(T);
    reg::CorrespondenceSet pairs;
    double error = 0.0;
    for (size_t i = 0; i < moved.points_.size(); ++i) {
      if (model.tree.SearchKNN(moved.points_[i], 1, index, squared) > 0 &&
          squared[0] <= distance_m * distance_m) {
        pairs.emplace_back(static_cast<int>(i), index[0]);
        error += squared[0];
      }
    }
    const double fitness =
        static_cast<double>(pairs.size()) / std::max<size_t>(1, moved.points_.size());
    const double rmse = pairs.empty() ? 0.0 : std::sqrt(error / pairs.size());
    const bool settled = iteration > 0 && std::abs(fitness - result.fitness_) < 1e-3 &&
                         std::abs(rmse - result.inlier_rmse_) < 1e-2 * result.inlier_rmse_;
    result.transformation_ = T;
    result.fitness_ = fitness;
    result.inlier_rmse_ = rmse;
    if (settled || iteration == 30 || pairs.size() < 3) break;
    T = estimation.ComputeTransformation(moved, *model.cloud, pairs) * T;
  }
  return result;
}

}  // namespace

Result<MeshRegistration> TrackMeshPose(const MeshSurface& surface,
                                       const std::vector<Eigen::Vector3d>& observed_C,
                                       const Eigen::Isometry3d& X_CS, double capture_m,
                                       double noise_sigma_m) {
  if (observed_C.size() < 30) {
    return Status::InvalidArgument(
        fmt::format("tracking: {} observed points of the object (at least 30)", observed_C.size()));
  }
  const size_t every = (observed_C.size() + kTrackingPoints - 1) / kTrackingPoints;
  o3d::geometry::PointCloud observed;
  for (size_t i = 0; i < observed_C.size(); i += every) observed.points_.push_back(observed_C[i]);
  const reg::RegistrationResult coarse =
      IcpOnSurface(observed, surface.samples(), capture_m, X_CS.inverse().matrix());
  const double fine_m = std::min(capture_m, std::max(3.0 * noise_sigma_m, 1e-4));
  return FromIcp(IcpOnSurface(observed, surface.samples(), fine_m, coarse.transformation_), fine_m);
}

}  // namespace softid::ingest
