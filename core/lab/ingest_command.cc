// softid-lab ingest RECORDING -o CAPTURE: a raw recording (softid-recording/1) turned into a
// capture (softid-capture/1) plus ingest.json and ingest.png, and a summary of what was found.
#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <filesystem>

#include "core/ingest/ingest.h"
#include "core/lab/commands.h"
#include "core/recording/recording.h"

namespace softid::lab {
namespace {

struct IngestFlags {
  std::string recording;
  std::string out;
};

int ExitCodeFor(const Status& status) {
  return status.code() == StatusCode::kIoError || status.code() == StatusCode::kInternal
             ? kExitFailure
             : kExitInvalidInput;
}

void PrintSummary(const ingest::IngestReport& report, double seconds,
                  const std::filesystem::path& out) {
  const ingest::IngestStageSeconds& stage = report.seconds;
  std::printf(
      "ingested in %.1f s into %s (static scene %.1f s, floor %.1f s, segmentation %.1f s, mesh "
      "pose %.1f s, masks completed and written %.1f s, finishing %.1f s)\n",
      seconds, out.c_str(), stage.static_scene, stage.floor, stage.segmentation, stage.registration,
      stage.masks, stage.finishing);
  for (const ingest::CameraIngest& camera : report.cameras) {
    int found = 0;
    for (const int pixels : camera.object_pixels) found += pixels > 0 ? 1 : 0;
    std::printf("  camera %-8s object in %d of %zu frames (static scene from %s)\n",
                camera.name.c_str(), found, camera.object_pixels.size(),
                camera.static_from_background ? "background frames" : "the frames");
    if (camera.cut_off) {
      std::printf("    warning: the object touches this camera's image border in every frame\n");
    }
  }
  std::printf("  floor      %d points (%.0f %%), RMS %.2f mm%s\n", report.floor_C.inliers,
              100 * report.floor_C.inlier_share, 1e3 * report.floor_C.rms_m,
              report.world_from_floor ? "; world frame built on it" : "");
  std::printf("  mesh pose  overlap %.1f %%, RMS %.2f mm\n", 100 * report.registration.overlap,
              1e3 * report.registration.rms_m);
  std::printf("  frames     %zu, median interval %.2f ms, longest gap %.2f ms\n",
              report.frame_times_s.size(), 1e3 * report.median_interval_s, 1e3 * report.max_gap_s);
}

int RunIngest(const IngestFlags& flags) {
  if (const Result<recording::FolderFormat> format = recording::DetectFolderFormat(flags.recording);
      format.ok() && *format == recording::FolderFormat::kCapture) {
    spdlog::error(
        "{}: a capture already (capture.json), not a recording: fit it directly with "
        "softid-lab fit",
        flags.recording);
    return kExitInvalidInput;
  }
  Result<recording::Recording> recording = recording::ReadRecording(flags.recording);
  if (!recording.ok()) {
    spdlog::error("{}", recording.status().message());
    return ExitCodeFor(recording.status());
  }
  const auto start = std::chrono::steady_clock::now();
  std::string last_stage;
  Result<ingest::IngestReport> report =
      ingest::Ingest(*recording, flags.out, {}, [&](std::string_view stage, int done, int total) {
        if (stage != last_stage || done == total) {
          spdlog::info("ingest: {} {}/{}", stage, done, total);
          last_stage = stage;
        }
      });
  if (!report.ok()) {
    spdlog::error("{}", report.status().message());
    return ExitCodeFor(report.status());
  }
  PrintSummary(*report,
               std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
               flags.out);
  return kExitOk;
}

}  // namespace

Command RegisterIngest(CLI::App* app) {
  app->footer(
      "Example:\n"
      "  softid-lab ingest recording/ -o capture/      # then: softid-lab fit capture/ ...");
  auto flags = std::make_shared<IngestFlags>();
  app->add_option("recording", flags->recording, "recording folder (softid-recording/1)")
      ->required();
  app->add_option("-o,--out", flags->out, "capture folder to write (softid-capture/1)")->required();
  app->footer(
      "Example:\n  softid-lab synth --raw --out rec && softid-lab ingest rec -o cap && "
      "softid-lab fit cap");
  return [flags] { return RunIngest(*flags); };
}

}  // namespace softid::lab
