#include "core/scenes/synthesize.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/capture/capture.h"
#include "core/fem/physical_parameters.h"

namespace softid::scenes {
namespace {

std::filesystem::path FreshDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("softid_scenes_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  return dir;
}

SynthesisOptions SmallOptions() {
  SynthesisOptions options;
  options.run.simulation.cells_along_longest_side = 8;
  options.run.substeps_per_frame = 2;
  options.run.duration = 0.25;
  options.cameras.count = 2;
  options.cameras.width = 32;
  options.cameras.height = 24;
  return options;
}

// A synthesised capture is accepted by the capture reader unchanged, with one frame per 1/fps per
// camera showing the object, truth.json holding the scene's parameters under the public names
// and the generator's grid, and mass_kg = density x mesh volume.
TEST(Synthesize, WritesACaptureTheReaderAccepts) {
  Result<Scene> scene = MakeBuiltinScene("ball-bounce");
  ASSERT_TRUE(scene.ok());
  const auto dir = FreshDir("ball");
  const Result<SynthesisSummary> summary = Synthesize(*scene, SmallOptions(), dir);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_FALSE(summary->run.diverged);

  const Result<capture::Capture> cap = capture::ReadCapture(dir);
  ASSERT_TRUE(cap.ok()) << cap.status().ToString();
  EXPECT_EQ(cap->NumCameras(), 2);
  EXPECT_EQ(cap->NumFrames(), 16);  // floor(0.25 * 60) + 1
  ASSERT_TRUE(cap->mass_kg.has_value());
  EXPECT_NEAR(*cap->mass_kg,
              scene->parameters.density * std::abs(geometry::SignedVolume(scene->mesh)), 1e-9);
  for (int camera = 0; camera < 2; ++camera) {
    for (int frame : {0, 15}) {
      const auto image = capture::LoadFrame(*cap, camera, frame);
      ASSERT_TRUE(image.ok()) << image.status().ToString();
      EXPECT_GT(image->NumValid(), 10) << "camera " << camera << " frame " << frame;
    }
  }

  std::ifstream file(dir / kTruthFileName);
  const nlohmann::json truth = nlohmann::json::parse(file);
  EXPECT_EQ(truth["format"], kTruthFormat);
  const auto parameters = fem::PhysicalParametersFromJson(truth["parameters"]);
  ASSERT_TRUE(parameters.ok()) << parameters.status().ToString();
  EXPECT_EQ(fem::ToJson(*parameters), fem::ToJson(scene->parameters));
  // The generator's discretisation, to tell a fit's grid error from its own.
  const SynthesisOptions options = SmallOptions();
  EXPECT_EQ(truth["generator"]["cells_along_longest_side"],
            options.run.simulation.cells_along_longest_side);
  EXPECT_EQ(truth["generator"]["cut_cell_samples"], options.run.simulation.cut_cell_samples);
  EXPECT_TRUE(std::filesystem::exists(dir / kPreviewFileName));
  std::filesystem::remove_all(dir);
}

// The ball falls: its pixels move down the image between the first and a later frame, so the
// frames show the simulation, not the rest pose.
TEST(Synthesize, FramesShowTheMotion) {
  Result<Scene> scene = MakeBuiltinScene("ball-bounce");
  ASSERT_TRUE(scene.ok());
  const auto dir = FreshDir("motion");
  ASSERT_TRUE(Synthesize(*scene, SmallOptions(), dir).ok());
  const auto cap = capture::ReadCapture(dir);
  ASSERT_TRUE(cap.ok());
  auto mean_row = [&](int frame) {
    const auto image = capture::LoadFrame(*cap, 0, frame);
    double sum = 0.0;
    int count = 0;
    for (int r = 0; r < image->height; ++r) {
      for (int c = 0; c < image->width; ++c) {
        if (image->at(c, r) > 0.0f) {
          sum += r;
          ++count;
        }
      }
    }
    return sum / count;
  };
  EXPECT_GT(mean_row(15), mean_row(0) + 1.0);  // image rows grow downwards
  std::filesystem::remove_all(dir);
}

// Writing over an existing capture is refused, and the existing capture is left intact.
TEST(Synthesize, RefusesToOverwriteACapture) {
  Result<Scene> scene = MakeBuiltinScene("bar-hanging");
  ASSERT_TRUE(scene.ok());
  const auto dir = FreshDir("overwrite");
  SynthesisOptions options = SmallOptions();
  options.run.duration = 0.05;
  ASSERT_TRUE(Synthesize(*scene, options, dir).ok());
  const Result<SynthesisSummary> again = Synthesize(*scene, options, dir);
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.status().message().find("already holds a capture"), std::string::npos);
  EXPECT_TRUE(capture::ReadCapture(dir).ok());
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace softid::scenes
