#include "core/diagnosis/fit_report.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include "core/common/json_fields.h"
#include "core/diagnosis/plots.h"
#include "core/diagnosis/residual_map.h"
#include "core/diagnosis/surface_overlay.h"
#include "core/inverse/objective_settings.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::diagnosis {
namespace {

// Patches only label residuals for the diagnosis; the report needs none apart from one.
constexpr int kPatches = 1;

Series StartCostSeries(const inverse::StartResult& start, int index, bool best) {
  Series out;
  out.label = "start " + std::to_string(index + 1) + (best ? " (best)" : "");
  out.y.push_back(start.initial_cost);
  for (double c : start.CostHistoryOverEveryFrame()) out.y.push_back(c);
  for (size_t i = 0; i < out.y.size(); ++i) out.x.push_back(static_cast<double>(i));
  return out;
}

// Indices into the observed frames: `count` spread evenly after the release (index 0 shows the
// given rest pose) up to the last, the one nearest the worst-fitting frame replaced by it;
// ascending and distinct.
std::vector<int> SnapshotIndices(const ResidualMap& map, int count) {
  const int n = static_cast<int>(map.frames.size());
  int worst = 0;
  for (int k = 0; k < n; ++k)
    if (map.frames[k].misfit > map.frames[worst].misfit) worst = k;
  std::vector<int> out;
  for (int i = 1; i <= count; ++i)
    out.push_back(static_cast<int>(std::lround(i * (n - 1.0) / count)));
  const auto nearest = std::min_element(out.begin(), out.end(), [&](int a, int b) {
    return std::abs(a - worst) < std::abs(b - worst);
  });
  *nearest = worst;
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// The first camera's direction of sight (the "front" view), or the world's y when level with up.
Eigen::Vector3d FrontDirection(const capture::Capture& capture, const Eigen::Vector3d& up) {
  if (capture.cameras.empty()) return up.unitOrthogonal();
  const Eigen::Vector3d sight = capture.cameras[0].camera.X_WC.linear().col(2);
  const Eigen::Vector3d level = sight - sight.dot(up) * up;
  return level.norm() > 1e-6 ? level.normalized() : up.unitOrthogonal();
}

// The cost per iteration of every start that did not fail: cost_per_iteration.png.
Status WriteCostPlot(const inverse::FitResult& fit, const std::filesystem::path& dir,
                     FitReport* report) {
  std::vector<Series> series;
  for (size_t i = 0; i < fit.starts.size(); ++i) {
    if (!fit.starts[i].failed)
      series.push_back(StartCostSeries(fit.starts[i], static_cast<int>(i), fit.best == int(i)));
  }
  SOFTID_RETURN_IF_ERROR(WriteCostHistoryPlot(dir / "cost_per_iteration.png", series));
  report->files.push_back("cost_per_iteration.png");
  return Status::Ok();
}

// The objective of the fitted parameters over the observed frames.
Result<std::unique_ptr<inverse::TrajectoryObjective>> MakeObjective(
    const capture::Capture& capture, const inverse::JobConfig& config,
    const geometry::TriangleMesh& mesh, const Observations& observations,
    const fem::PhysicalParameters& p) {
  try {
    return std::make_unique<inverse::TrajectoryObjective>(
        mesh, capture.fixed_region, p, inverse::SimulationOptionsFor(config.solver),
        inverse::CostOptionsFor(config.solver),
        std::make_shared<const std::vector<inverse::ObservedFrame>>(observations.frames),
        capture.fps, config.solver.substeps);
  } catch (const std::invalid_argument& e) {
    return Status::InvalidArgument(e.what());
  }
}

// The fitted parameters simulated once over the observed frames: the motion phase of each, and
// the simulated surface at each snapshot frame (ascending indices into the frames).
struct FittedRun {
  std::vector<FrameMotion> motion;
  std::vector<geometry::TriangleMesh> surfaces;
};

Result<FittedRun> RunFitted(fem::Simulator& sim, const fem::PhysicalParameters& p,
                            const ResidualMap& map, const std::vector<int>& snapshots,
                            const MotionPhaseOptions& options) {
  std::vector<FrameAt> times;
  for (const FrameResiduals& f : map.frames) times.push_back({f.frame, f.time});
  FittedRun run;
  size_t next = 0;
  const FrameVisitor keep_snapshots = [&](size_t index, const fem::Simulator& at_frame) {
    if (next < snapshots.size() && static_cast<size_t>(snapshots[next]) == index) {
      run.surfaces.push_back(at_frame.DeformedSurface());
      ++next;
    }
  };
  SOFTID_ASSIGN_OR_RETURN(run.motion, SplitMotionPhases(sim, p, times, options, keep_snapshots));
  return run;
}

// The misfit of every frame in noise floors, over the motion phases: residual_per_frame.png.
Status WriteMisfitPlot(const std::vector<FrameMotion>& motion, const ResidualMap& map,
                       const NoiseFloor& floor, const FitReportOptions& options,
                       const std::filesystem::path& dir, FitReport* report) {
  std::vector<int> frames;
  std::vector<double> normalised;
  for (const FrameResiduals& f : map.frames) {
    frames.push_back(f.frame);
    normalised.push_back(f.misfit / floor.sigma);
  }
  SOFTID_RETURN_IF_ERROR(WriteFrameMisfitPlot(dir / "residual_per_frame.png", frames, normalised,
                                              {}, motion, options.misfit_threshold,
                                              "fitted simulation"));
  report->files.push_back("residual_per_frame.png");
  return Status::Ok();
}

// The simulated surface over the observed points at the snapshot frames (`wanted`, with their
// `surfaces`), the worst-fitting among them: surface_overlay.png.
Status WriteSnapshots(const capture::Capture& capture, const fem::PhysicalParameters& p,
                      const Observations& observations, const ResidualMap& map,
                      const NoiseFloor& floor, const Eigen::Vector3d& up,
                      const std::vector<int>& wanted, std::vector<geometry::TriangleMesh> surfaces,
                      const std::filesystem::path& dir, FitReport* report) {
  std::vector<SurfaceSnapshot> snapshots;
  for (size_t i = 0; i < wanted.size(); ++i) {
    const FrameResiduals& f = map.frames[wanted[i]];
    snapshots.push_back({f.frame, f.time, std::move(surfaces[i]),
                         observations.frames[wanted[i]].points, f.phi, f.matched});
    report->snapshot_frames.push_back(f.frame);
  }
  SurfaceOverlayView view;
  view.up_W = up;
  view.front_W = FrontDirection(capture, up);
  view.noise_floor_m = floor.sigma;
  view.ground = p.ground;
  SOFTID_RETURN_IF_ERROR(WriteSurfaceOverlay(dir / "surface_overlay.png", snapshots, view));
  report->files.push_back("surface_overlay.png");
  return Status::Ok();
}

}  // namespace

Status FitReportOptions::Validate() const {
  if (snapshots < 1 || snapshots > 8)
    return json::Invalid("snapshots", snapshots, "must lie in [1, 8]");
  if (!(misfit_threshold > 0.0) || !std::isfinite(misfit_threshold))
    return json::Invalid("misfit_threshold", misfit_threshold, "must be positive");
  SOFTID_RETURN_IF_ERROR(noise_floor.Validate());
  return phases.Validate();
}

Result<FitReport> WriteFitReport(const capture::Capture& capture,
                                 const inverse::JobConfig& config_in, const inverse::FitResult& fit,
                                 const std::filesystem::path& dir,
                                 const FitReportOptions& options) {
  const auto begin = std::chrono::steady_clock::now();
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (fit.best < 0) return Status::FailedPrecondition("the fit has no successful start to report");
  const inverse::JobConfig config = inverse::WithFitDiscretisation(config_in, fit);
  const fem::PhysicalParameters& p = fit.Best().final;
  FitReport report;
  SOFTID_RETURN_IF_ERROR(WriteCostPlot(fit, dir, &report));

  SOFTID_ASSIGN_OR_RETURN(geometry::TriangleMesh mesh, capture::LoadCaptureMesh(capture));
  SOFTID_ASSIGN_OR_RETURN(
      Observations observations,
      LoadObservations(capture, config.frames.first, config.frames.last, config.heldout_every));
  SOFTID_ASSIGN_OR_RETURN(std::unique_ptr<inverse::TrajectoryObjective> objective,
                          MakeObjective(capture, config, mesh, observations, p));
  objective->SetCancelFlag(options.cancel);
  SOFTID_ASSIGN_OR_RETURN(auto matches, objective->MatchPoints(p));
  fem::Simulator& sim = objective->simulator();
  // Up in the grid's frame, where the rest surface lies (fem::Simulator::mesh_from_grid).
  const Eigen::Vector3d up =
      sim.rest_frame().world_from_rest().linear().transpose() * -p.gravity.normalized();
  const ResidualMap map =
      BuildResidualMap(observations, matches, MakePatches(sim.rest_surface(), kPatches, up),
                       config.solver.cost.truncation_cells * sim.hex_mesh().CellSize());
  SOFTID_ASSIGN_OR_RETURN(const NoiseFloor floor, EstimateNoiseFloor(map, options.noise_floor));
  report.noise_floor_m = floor.sigma;

  const std::vector<int> wanted = SnapshotIndices(map, options.snapshots);
  SOFTID_ASSIGN_OR_RETURN(FittedRun run, RunFitted(sim, p, map, wanted, options.phases));
  SOFTID_RETURN_IF_ERROR(WriteMisfitPlot(run.motion, map, floor, options, dir, &report));
  SOFTID_RETURN_IF_ERROR(WriteSnapshots(capture, p, observations, map, floor, up, wanted,
                                        std::move(run.surfaces), dir, &report));
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
  return report;
}

nlohmann::json ToJson(const FitReport& report) {
  return {{"files", report.files},
          {"noise_floor_m", report.noise_floor_m},
          {"snapshot_frames", report.snapshot_frames},
          {"seconds", report.seconds}};
}

}  // namespace softid::diagnosis
