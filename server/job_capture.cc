#include "server/job_capture.h"

#include "server/materialize_capture.h"
#include "server/recording_ingest.h"

namespace softid::server {

Result<capture::Capture> PrepareCapture(const store::Job& job, const store::Capture& stored,
                                        const std::string& worker_id,
                                        const JobRunnerContext& context,
                                        const std::filesystem::path& dir,
                                        const std::atomic<bool>& cancel,
                                        nlohmann::json* ingest_report) {
  store::Capture fitted = stored;
  std::filesystem::path capture_dir = dir;
  if (stored.format == store::kRecordingFormat) {
    Result<IngestedCapture> ingested =
        job.derived_capture_id.empty()
            ? IngestRecording(job, stored, worker_id, context, dir, &cancel)
            : LoadIngestedCapture(job, context);
    if (!ingested.ok()) return ingested.status();
    if (!job.derived_capture_id.empty()) {
      context.logger->info("job {}: ingest skipped: capture {} was derived on an earlier attempt",
                           job.id, job.derived_capture_id);
    }
    *ingest_report = std::move(ingested->report);
    fitted = std::move(ingested->capture);
    capture_dir = dir / "capture";
  }
  if (Status laid_out = MaterializeCapture(fitted, *context.blobs, capture_dir); !laid_out.ok()) {
    return laid_out.WithContext("capture " + fitted.id);
  }
  // Frames were decoded at upload (or written by the ingest); headers suffice here.
  Result<capture::Capture> capture =
      capture::ReadCapture(capture_dir, capture::ReadCaptureOptions{.decode_frames = false});
  if (!capture.ok()) return capture.status().WithContext("capture " + fitted.id);
  return capture;
}

}  // namespace softid::server
