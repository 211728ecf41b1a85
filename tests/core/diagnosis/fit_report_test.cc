// The pictures of a fit's report, drawn from a synthetic capture at given parameters: the files
// are written and readable, and the overlay colours the observed points by how far they lie from
// the simulated surface (a wrong Young's modulus paints far more of them red than the truth).
#include "core/diagnosis/fit_report.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "core/diagnosis/surface_overlay.h"
#include "core/scenes/scene.h"
#include "core/scenes/synthesize.h"

namespace softid::diagnosis {
namespace {

namespace fs = std::filesystem;

struct TorusCapture {
  fs::path dir = fs::temp_directory_path() / ("softid_fit_report_" + std::to_string(::getpid()));
  capture::Capture capture;
  fem::PhysicalParameters truth;

  TorusCapture() {
    fs::remove_all(dir);
    Result<scenes::Scene> scene = scenes::MakeBuiltinScene("torus-drop");
    EXPECT_TRUE(scene.ok());
    truth = scene->parameters;
    scenes::SynthesisOptions options;
    options.run.simulation.cells_along_longest_side = 10;
    options.run.substeps_per_frame = 2;
    options.run.duration = 0.4;
    options.cameras.width = 64;
    options.cameras.height = 48;
    EXPECT_TRUE(scenes::Synthesize(*scene, options, dir).ok());
    capture = *capture::ReadCapture(dir);
  }
  ~TorusCapture() {
    std::error_code ignored;
    fs::remove_all(dir, ignored);
  }
  // The capture's own discretisation, so that the truth fits to the noise.
  inverse::JobConfig Config() const {
    inverse::JobConfig config;
    config.fit = {"youngs_modulus"};
    config.solver.cells = 10;
    config.solver.substeps = 2;
    config.solver.threads = 1;
    return config;
  }
};

// A fit's result as if its one start had ended at `p`, with a short cost history.
inverse::FitResult EndedAt(const fem::PhysicalParameters& p, const inverse::JobConfig& config) {
  inverse::StartResult start;
  start.initial = start.final = p;
  start.initial_cost = 4e-5;
  start.final_cost = 1e-5;
  start.cost_history = {2e-5, 1e-5};
  start.cost_history_last_frame = {24, 24};
  inverse::FitResult fit;
  fit.fitted = config.fit;
  fit.base = p;
  fit.starts = {start};
  fit.best = 0;
  fit.cells = config.solver.cells;
  fit.substeps = config.solver.substeps;
  return fit;
}

// Pixels of the image in the residual scale's red (three noise floors and more).
int RedPixels(const fs::path& png) {
  const cv::Mat image = cv::imread(png.string(), cv::IMREAD_COLOR);
  EXPECT_FALSE(image.empty()) << png;
  int red = 0;
  for (int r = 0; r < image.rows; ++r) {
    for (int c = 0; c < image.cols; ++c) red += image.at<cv::Vec3b>(r, c) == cv::Vec3b(0, 0, 255);
  }
  return red;
}

TEST(FitReport, WritesItsPicturesAndPaintsAWrongModulusRed) {
  TorusCapture torus;
  const inverse::JobConfig config = torus.Config();
  const fs::path truth_dir = torus.dir / "report_truth";
  Result<FitReport> at_truth =
      WriteFitReport(torus.capture, config, EndedAt(torus.truth, config), truth_dir);
  ASSERT_TRUE(at_truth.ok()) << at_truth.status().ToString();
  EXPECT_EQ(at_truth->files,
            (std::vector<std::string>{"cost_per_iteration.png", "residual_per_frame.png",
                                      "surface_overlay.png"}));
  for (const std::string& file : at_truth->files) {
    const cv::Mat image = cv::imread((truth_dir / file).string());
    EXPECT_GT(image.cols, 300) << file;
  }
  EXPECT_GT(at_truth->noise_floor_m, 0.0);
  ASSERT_EQ(at_truth->snapshot_frames.size(), 3u);
  EXPECT_LT(at_truth->snapshot_frames[0], at_truth->snapshot_frames[1]);
  EXPECT_LT(at_truth->snapshot_frames[1], at_truth->snapshot_frames[2]);

  fem::PhysicalParameters stiff = torus.truth;
  stiff.youngs_modulus *= 4.0;
  const fs::path stiff_dir = torus.dir / "report_stiff";
  ASSERT_TRUE(WriteFitReport(torus.capture, config, EndedAt(stiff, config), stiff_dir).ok());
  const int red_truth = RedPixels(truth_dir / "surface_overlay.png");
  const int red_stiff = RedPixels(stiff_dir / "surface_overlay.png");
  EXPECT_GT(red_stiff, 2 * red_truth + 100) << red_truth << " vs " << red_stiff;
}

TEST(FitReport, RejectsBadOptionsAndAFitWithoutAStart) {
  TorusCapture torus;
  const inverse::JobConfig config = torus.Config();
  FitReportOptions options;
  options.snapshots = 0;
  Result<FitReport> report =
      WriteFitReport(torus.capture, config, EndedAt(torus.truth, config), torus.dir / "r", options);
  ASSERT_FALSE(report.ok());
  EXPECT_NE(report.status().message().find("snapshots"), std::string::npos);
  inverse::FitResult none = EndedAt(torus.truth, config);
  none.best = -1;
  report = WriteFitReport(torus.capture, config, none, torus.dir / "r");
  EXPECT_EQ(report.status().code(), StatusCode::kFailedPrecondition);
}

TEST(SurfaceOverlay, RejectsResidualsThatDoNotMatchThePoints) {
  SurfaceSnapshot s;
  s.points = {Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX()};
  s.phi = {0.0f};
  s.matched = {1, 1};
  SurfaceOverlayView view;
  view.noise_floor_m = 0.001;
  const fs::path png = fs::temp_directory_path() / "softid_overlay_never_written.png";
  EXPECT_EQ(WriteSurfaceOverlay(png, {s}, view).code(), StatusCode::kInvalidArgument);
  s.phi = {0.0f, 0.0f};
  view.noise_floor_m = 0.0;
  EXPECT_EQ(WriteSurfaceOverlay(png, {s}, view).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(png));
}

}  // namespace
}  // namespace softid::diagnosis
