#include "core/scenes/raw_recording_synthesis.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/capture/pixel_rays.h"
#include "core/recording/recording.h"
#include "core/scenes/synthesize.h"

namespace softid::scenes {
namespace {

std::filesystem::path FreshDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("softid_raw_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  return dir;
}

Eigen::Isometry3d Pose(const nlohmann::json& numbers) {
  Eigen::Matrix4d m;
  for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = numbers.at(i).get<double>();
  return Eigen::Isometry3d(m);
}

Eigen::Vector3d Vec(const nlohmann::json& v) {
  return {v.at(0).get<double>(), v.at(1).get<double>(), v.at(2).get<double>()};
}

nlohmann::json ReadTruth(const std::filesystem::path& dir) {
  std::ifstream file(dir / kTruthFileName);
  return nlohmann::json::parse(file);
}

// A short torus drop: 0.2 s at 60 fps (13 ideal frames), one 80x60 camera.
RawSynthesisOptions SmallOptions() {
  RawSynthesisOptions options;
  options.run.simulation.cells_along_longest_side = 8;
  options.run.substeps_per_frame = 2;
  options.run.duration = 0.2;
  options.cameras.width = 80;
  options.cameras.height = 60;
  options.noise = capture::StructuredLightNoise(7);
  options.depth_scale = 1e-3;
  options.drop_fraction = 0.2;  // round(0.2 * 12) = 2 frames dropped
  options.background_frames = 2;
  options.write_true_masks = true;
  options.seed = 11;
  return options;
}

double Sigma(double z) {
  return 1.5e-3 + 2.5e-3 * z * z;
}

class RawTorusDrop : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    Result<Scene> made = MakeBuiltinScene("torus-drop");
    ASSERT_TRUE(made.ok()) << made.status().ToString();
    scene_ = new Scene(*made);
    dir_ = new std::filesystem::path(FreshDir("torus"));
    Result<RawSynthesisSummary> summary = SynthesizeRawRecording(*scene_, SmallOptions(), *dir_);
    ASSERT_TRUE(summary.ok()) << summary.status().ToString();
    summary_ = new RawSynthesisSummary(*summary);
  }
  static void TearDownTestSuite() {
    if (dir_) std::filesystem::remove_all(*dir_);
    delete scene_;
    delete dir_;
    delete summary_;
  }
  void SetUp() override { ASSERT_NE(summary_, nullptr); }

  static Scene* scene_;
  static std::filesystem::path* dir_;
  static RawSynthesisSummary* summary_;
};
Scene* RawTorusDrop::scene_ = nullptr;
std::filesystem::path* RawTorusDrop::dir_ = nullptr;
RawSynthesisSummary* RawTorusDrop::summary_ = nullptr;

// The recording reader accepts the folder: one camera without a pose, distortion as asked, time
// stamps on a device clock starting 1000..1100 s and strictly increasing, two frames dropped.
TEST_F(RawTorusDrop, ReaderAcceptsItWithDeviceClockAndDroppedFrames) {
  const Result<recording::Recording> rec = recording::ReadRecording(*dir_);
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  ASSERT_EQ(rec->NumCameras(), 1);
  const recording::RecordingCamera& cam = rec->cameras[0];
  EXPECT_FALSE(cam.has_world_from_camera);
  EXPECT_EQ(cam.distortion, SmallOptions().distortion);
  EXPECT_EQ(cam.camera.width, 80);
  EXPECT_EQ(cam.camera.height, 60);
  EXPECT_EQ(cam.frames.size(), 11u);  // 13 - 2
  EXPECT_EQ(summary_->num_dropped, 2);
  EXPECT_EQ(cam.background.size(), 2u);
  const nlohmann::json truth = ReadTruth(*dir_);
  EXPECT_EQ(truth["format"], kTruthFormat);
  const double offset = truth["raw"]["time_offset_s"].get<double>();
  EXPECT_GE(offset, 1000.0);
  EXPECT_LE(offset, 1100.0);
  const auto& times = truth["raw"]["frame_times_s"];
  const auto& indices = truth["raw"]["frame_indices"];
  ASSERT_EQ(times.size(), cam.frames.size());
  EXPECT_EQ(indices[0].get<int>(), 0);  // frame 0 is never dropped
  bool gap = false;
  for (size_t i = 0; i < cam.frames.size(); ++i) {
    EXPECT_NEAR(cam.frames[i].time_s, offset + times[i].get<double>(), 1e-9);
    // Jitter of 1 ms (truncated at 2 sigma) around k / 60.
    EXPECT_NEAR(times[i].get<double>(), indices[i].get<int>() / 60.0, 2.0e-3 + 1e-12);
    if (i > 0) {
      EXPECT_GT(cam.frames[i].time_s, cam.frames[i - 1].time_s);
      const double dt = cam.frames[i].time_s - cam.frames[i - 1].time_s;
      if (dt > 1.5 / 60.0) gap = true;
    }
  }
  EXPECT_TRUE(gap) << "dropped frames leave gaps in the time stamps";
  bool jittered = false;
  for (size_t i = 1; i < times.size(); ++i) {
    if (std::abs(times[i].get<double>() - indices[i].get<int>() / 60.0) > 1e-5) jittered = true;
  }
  EXPECT_TRUE(jittered);
  EXPECT_EQ(rec->mesh_unit, recording::MeshUnit::kMillimetre);
  ASSERT_TRUE(rec->mass_kg.has_value());
}

// The scan, in millimetres in a random scanner frame, maps onto the scene's rest mesh through the
// true world_from_scanner.
TEST_F(RawTorusDrop, MeshInScannerFrameMatchesRestMesh) {
  const Result<recording::Recording> rec = recording::ReadRecording(*dir_);
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  const Result<geometry::TriangleMesh> scan = recording::LoadRecordingMesh(*rec);
  ASSERT_TRUE(scan.ok()) << scan.status().ToString();
  const Eigen::Isometry3d X_WS = Pose(ReadTruth(*dir_)["raw"]["world_from_scanner"]);
  EXPECT_TRUE(X_WS.isApprox(summary_->world_from_scanner, 1e-12));
  const double shift = X_WS.translation().norm();
  EXPECT_GE(shift, 0.1 - 1e-9);
  EXPECT_LE(shift, 1.0 + 1e-9);
  ASSERT_EQ(scan->vertices.size(), scene_->mesh.vertices.size());
  // The mesh reader may reorder vertices: match each to its nearest rest vertex.
  double worst = 0.0, moved = 0.0;
  for (const Eigen::Vector3d& v_S : scan->vertices) {
    const Eigen::Vector3d v_W = X_WS * v_S;
    double nearest = 1e300;
    for (const Eigen::Vector3d& rest : scene_->mesh.vertices) {
      nearest = std::min(nearest, (v_W - rest).squaredNorm());
    }
    worst = std::max(worst, std::sqrt(nearest));
    moved = std::max(moved, (v_W - v_S).norm());
  }
  EXPECT_LT(worst, 1e-6);
  EXPECT_GT(moved, 0.05) << "the scan is not in the world frame";
}

// Frame 0 shows the floor: a large share of its pixels, unprojected through the lens's pixel
// rays and the true camera pose, lie on the true floor plane within 2 mm plus the noise.
TEST_F(RawTorusDrop, FloorFillsMuchOfTheImage) {
  const Result<recording::Recording> rec = recording::ReadRecording(*dir_);
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  const nlohmann::json truth = ReadTruth(*dir_);
  const Eigen::Vector3d n = Vec(truth["raw"]["floor"]["normal"]);
  const double d = truth["raw"]["floor"]["offset"].get<double>();
  EXPECT_TRUE(n.isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  EXPECT_NEAR(d, 0.0, 1e-12);
  const Eigen::Isometry3d X_WC = Pose(truth["raw"]["cameras"][0]["world_from_camera"]);
  const auto& cam = rec->cameras[0];
  const Result<capture::PixelRays> rays = capture::ComputePixelRays(cam.camera, cam.distortion);
  ASSERT_TRUE(rays.ok());
  const Result<capture::DepthImage> image = recording::LoadRecordingFrame(*rec, 0, 0);
  ASSERT_TRUE(image.ok()) << image.status().ToString();
  int on_floor = 0, lower_half_on_floor = 0;
  for (int row = 0; row < image->height; ++row) {
    for (int col = 0; col < image->width; ++col) {
      const double z = image->at(col, row);
      if (z <= 0.0) continue;
      const Eigen::Vector2d& xy = rays->at(col, row);
      const Eigen::Vector3d p_W = X_WC * Eigen::Vector3d(z * xy.x(), z * xy.y(), z);
      if (std::abs(n.dot(p_W) - d) < 2e-3 + 3.0 * Sigma(z) + 0.5e-3) {
        ++on_floor;
        if (row >= image->height / 2) ++lower_half_on_floor;
      }
    }
  }
  const int pixels = image->width * image->height;
  EXPECT_GT(on_floor, pixels / 4) << on_floor << " of " << pixels;
  EXPECT_GT(lower_half_on_floor, pixels / 2 * 6 / 10) << "the floor fills the lower half";
  EXPECT_GT(image->NumValid(), pixels * 9 / 10) << "the whole scene has depth, not just the object";
}

// The clutter box stands at the same place in every frame: the pixels around its centre's image
// unproject into the true box.
TEST_F(RawTorusDrop, ClutterInEveryFrameAtTheSamePlace) {
  const Result<recording::Recording> rec = recording::ReadRecording(*dir_);
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  const nlohmann::json truth = ReadTruth(*dir_);
  const Eigen::Isometry3d X_WC = Pose(truth["raw"]["cameras"][0]["world_from_camera"]);
  const Eigen::Isometry3d X_WB = Pose(truth["raw"]["clutter"]["world_from_box"]);
  const Eigen::Vector3d size = Vec(truth["raw"]["clutter"]["size"]);
  const Eigen::Vector3d floor_n = Vec(truth["raw"]["floor"]["normal"]);
  // Stands on the floor.
  const Eigen::Vector3d bottom = X_WB * Eigen::Vector3d(0, 0, -0.5 * size.z());
  EXPECT_NEAR(floor_n.dot(bottom) - truth["raw"]["floor"]["offset"].get<double>(), 0.0, 1e-9);
  const auto& cam = rec->cameras[0];
  const Result<capture::PixelRays> rays = capture::ComputePixelRays(cam.camera, cam.distortion);
  ASSERT_TRUE(rays.ok());
  const Eigen::Vector2d uv =
      capture::ProjectDistorted(cam.camera, cam.distortion, X_WC.inverse() * X_WB.translation());
  const int col0 = static_cast<int>(std::lround(uv.x())),
            row0 = static_cast<int>(std::lround(uv.y()));
  ASSERT_GE(col0, 1);
  ASSERT_LT(col0, cam.camera.width - 1);
  ASSERT_GE(row0, 1);
  ASSERT_LT(row0, cam.camera.height - 1);
  const double tolerance = 0.015;  // noise at ~1 m and quantisation
  for (int frame = 0; frame < static_cast<int>(cam.frames.size()); ++frame) {
    const Result<capture::DepthImage> image = recording::LoadRecordingFrame(*rec, 0, frame);
    ASSERT_TRUE(image.ok()) << image.status().ToString();
    int inside = 0;
    for (int row = row0 - 1; row <= row0 + 1; ++row) {
      for (int col = col0 - 1; col <= col0 + 1; ++col) {
        const double z = image->at(col, row);
        if (z <= 0.0) continue;
        const Eigen::Vector2d& xy = rays->at(col, row);
        const Eigen::Vector3d p_B =
            X_WB.inverse() * (X_WC * Eigen::Vector3d(z * xy.x(), z * xy.y(), z));
        if ((p_B.cwiseAbs() - 0.5 * size).maxCoeff() < tolerance) ++inside;
      }
    }
    EXPECT_GE(inside, 6) << "frame " << frame;
  }
}

// The true mask of frame 0 marks the object, which hangs in the air: its pixels are nearer than
// the floor along their rays; background frames show no object there.
TEST_F(RawTorusDrop, TrueMaskMarksTheObjectAboveTheFloor) {
  const Result<recording::Recording> rec = recording::ReadRecording(*dir_);
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  const auto& cam = rec->cameras[0];
  const nlohmann::json truth = ReadTruth(*dir_);
  const Eigen::Isometry3d X_WC = Pose(truth["raw"]["cameras"][0]["world_from_camera"]);
  const Eigen::Vector3d n = Vec(truth["raw"]["floor"]["normal"]);
  const double d = truth["raw"]["floor"]["offset"].get<double>();
  for (int frame = 0; frame < static_cast<int>(cam.frames.size()); ++frame) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", frame);
    EXPECT_TRUE(std::filesystem::exists(*dir_ / kTrueMasksFolder / "cam0" / name)) << name;
  }
  const cv::Mat mask =
      cv::imread((*dir_ / kTrueMasksFolder / "cam0" / "000000.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(mask.empty());
  ASSERT_EQ(mask.type(), CV_8UC1);
  ASSERT_EQ(mask.cols, 80);
  ASSERT_EQ(mask.rows, 60);
  const Result<capture::PixelRays> rays = capture::ComputePixelRays(cam.camera, cam.distortion);
  ASSERT_TRUE(rays.ok());
  const Result<capture::DepthImage> image = recording::LoadRecordingFrame(*rec, 0, 0);
  const Result<capture::DepthImage> background = recording::LoadBackgroundFrame(*rec, 0, 0);
  ASSERT_TRUE(image.ok() && background.ok());
  int masked = 0, nearer = 0, checked = 0, background_nearer = 0;
  for (int row = 0; row < mask.rows; ++row) {
    for (int col = 0; col < mask.cols; ++col) {
      const uint8_t m = mask.at<uint8_t>(row, col);
      ASSERT_TRUE(m == 0 || m == 255);
      if (m == 0) continue;
      ++masked;
      const double z = image->at(col, row);
      if (z <= 0.0) continue;
      ++checked;
      const Eigen::Vector2d& xy = rays->at(col, row);
      const Eigen::Vector3d dir_W = X_WC.linear() * Eigen::Vector3d(xy.x(), xy.y(), 1.0);
      const double denom = n.dot(dir_W);
      // Depth along z at which this pixel's ray meets the floor (none: the ray looks up).
      const double z_floor = denom < 0.0 ? (d - n.dot(X_WC.translation())) / denom : 1e9;
      if (z < z_floor - 0.02) ++nearer;
      const double zb = background->at(col, row);
      if (zb > 0.0 && zb < z - 0.02) ++background_nearer;
    }
  }
  EXPECT_GT(masked, 50);
  EXPECT_GT(checked, masked / 2);
  EXPECT_EQ(nearer, checked);
  EXPECT_EQ(background_nearer, 0);
}

// Three cameras: every camera has its true pose in recording.json, in one world frame.
TEST(RawRecordingSynthesis, ThreeCamerasWritePoses) {
  Result<Scene> scene = MakeBuiltinScene("torus-drop");
  ASSERT_TRUE(scene.ok());
  RawSynthesisOptions options = SmallOptions();
  options.run.duration = 0.05;
  options.cameras.count = 3;
  options.write_true_masks = false;
  options.background_frames = 0;
  options.mesh_in_mm = false;
  const auto dir = FreshDir("three");
  const Result<RawSynthesisSummary> summary = SynthesizeRawRecording(*scene, options, dir);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  const Result<recording::Recording> rec = recording::ReadRecording(dir);
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  ASSERT_EQ(rec->NumCameras(), 3);
  EXPECT_EQ(rec->mesh_unit, recording::MeshUnit::kMetre);
  const nlohmann::json truth = ReadTruth(dir);
  for (int c = 0; c < 3; ++c) {
    const auto& cam = rec->cameras[c];
    EXPECT_TRUE(cam.has_world_from_camera) << c;
    EXPECT_TRUE(
        cam.camera.X_WC.isApprox(Pose(truth["raw"]["cameras"][c]["world_from_camera"]), 1e-12))
        << c;
    const Result<capture::DepthImage> image = recording::LoadRecordingFrame(*rec, c, 0);
    ASSERT_TRUE(image.ok());
    EXPECT_GT(image->NumValid(), 80 * 60 / 2) << "camera " << c << " sees the room";
  }
  EXPECT_FALSE(std::filesystem::exists(dir / kTrueMasksFolder));
  // A second run into the same folder is refused.
  const Result<RawSynthesisSummary> again = SynthesizeRawRecording(*scene, options, dir);
  EXPECT_EQ(again.status().code(), StatusCode::kFailedPrecondition);
  std::filesystem::remove_all(dir);
}

// A scanned mesh with holes (the Stanford bunny of the shared data) drops onto the floor as well.
TEST(RawRecordingSynthesis, ScannedBunny) {
  const auto path =
      std::filesystem::path(SOFTID_SHARED_DIR) / "data/meshes/stanford_bunny_res4.ply";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no shared meshes at " << path;
  Result<Scene> scene = MakeMeshScene(path.string());
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  RawSynthesisOptions options = SmallOptions();
  options.run.duration = 0.05;
  options.background_frames = 0;
  const auto dir = FreshDir("bunny");
  const Result<RawSynthesisSummary> summary = SynthesizeRawRecording(*scene, options, dir);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_GT(summary->mean_object_pixels, 30.0);
  const Result<recording::Recording> rec = recording::ReadRecording(dir);
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  const Result<geometry::TriangleMesh> scan = recording::LoadRecordingMesh(*rec);
  ASSERT_TRUE(scan.ok()) << scan.status().ToString();
  EXPECT_EQ(scan->vertices.size(), scene->mesh.vertices.size());
  std::filesystem::remove_all(dir);
}

// A recording written by `softid-lab synth --raw` (path in SOFTID_RAW_RECORDING_DIR) is accepted
// by the reader and every frame loads; skipped when the variable is unset.
TEST(RawRecordingSynthesis, ReadsCommandLineOutput) {
  const char* dir = std::getenv("SOFTID_RAW_RECORDING_DIR");
  if (dir == nullptr) GTEST_SKIP() << "SOFTID_RAW_RECORDING_DIR not set";
  const Result<recording::Recording> rec = recording::ReadRecording(dir);
  ASSERT_TRUE(rec.ok()) << rec.status().ToString();
  for (int c = 0; c < rec->NumCameras(); ++c) {
    for (int f = 0; f < static_cast<int>(rec->cameras[c].frames.size()); ++f) {
      const Result<capture::DepthImage> image = recording::LoadRecordingFrame(*rec, c, f);
      ASSERT_TRUE(image.ok()) << image.status().ToString();
      EXPECT_GT(image->NumValid(), image->width * image->height / 2);
    }
  }
  const Result<geometry::TriangleMesh> scan = recording::LoadRecordingMesh(*rec);
  EXPECT_TRUE(scan.ok()) << scan.status().ToString();
}

// Invalid options are rejected before anything is written.
TEST(RawRecordingSynthesis, RejectsInvalidOptions) {
  Result<Scene> scene = MakeBuiltinScene("torus-drop");
  ASSERT_TRUE(scene.ok());
  const auto dir = FreshDir("invalid");
  RawSynthesisOptions options = SmallOptions();
  options.drop_fraction = 1.0;
  EXPECT_EQ(SynthesizeRawRecording(*scene, options, dir).status().code(),
            StatusCode::kInvalidArgument);
  options = SmallOptions();
  options.distortion = {0.1, 0.2, 0.3};
  EXPECT_EQ(SynthesizeRawRecording(*scene, options, dir).status().code(),
            StatusCode::kInvalidArgument);
  options = SmallOptions();
  options.time_jitter_s = 0.1;
  EXPECT_EQ(SynthesizeRawRecording(*scene, options, dir).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_FALSE(std::filesystem::exists(dir));
}

}  // namespace
}  // namespace softid::scenes
