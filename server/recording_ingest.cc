#include "server/recording_ingest.h"

#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <mutex>
#include <shared_mutex>
#include <system_error>
#include <vector>

#include "core/ingest/ingest.h"
#include "core/recording/recording.h"
#include "server/materialize_capture.h"
#include "server/redact_paths.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;

constexpr std::string_view kIngestReportFile = "ingest.json";

// Records the ingest's progress as notes "ingest: <stage> <done>/<total>" in the job's history:
// a stage's first and last step and about ten in between, so a recording of thousands of frames
// does not flood the history (a watcher still sees it advance).
class IngestNotes {
 public:
  IngestNotes(const store::Job& job, const JobRunnerContext& context)
      : job_(job), context_(context) {}

  void operator()(std::string_view stage, int done, int total) {
    const int step = std::max(1, (total + 9) / 10);
    const bool new_stage = stage != stage_;
    if (!new_stage && done != total && done % step != 0) return;
    stage_ = std::string(stage);
    store::ProgressEvent note;
    note.kind = store::ProgressKind::kState;
    note.message = fmt::format("ingest: {} {}/{}", stage, done, total);
    if (Result<int64_t> seq = context_.jobs->AppendProgress(job_.id, note); !seq.ok()) {
      context_.logger->warn("job {}: ingest note not recorded: {}", job_.id,
                            seq.status().message());
    }
    context_.events->Notify(job_.id);
  }

 private:
  const store::Job& job_;
  const JobRunnerContext& context_;
  std::string stage_;
};

// Every regular file under `dir`, '/'-separated and relative to it, capture.json first.
Result<std::vector<std::string>> ListFiles(const fs::path& dir) {
  std::vector<std::string> files;
  std::error_code error;
  for (fs::recursive_directory_iterator it(dir, error), end; !error && it != end;
       it.increment(error)) {
    if (it->is_regular_file()) files.push_back(it->path().lexically_relative(dir).generic_string());
  }
  if (error) return Status::IoError("cannot list the ingested capture: " + error.message());
  std::sort(files.begin(), files.end(), [](const std::string& a, const std::string& b) {
    return std::make_pair(a != "capture.json", a) < std::make_pair(b != "capture.json", b);
  });
  return files;
}

// Stores the ingested capture folder `dir` as a capture of the job's owner: blobs first, then the
// row (as an upload does), with the blob lock held shared in between so that no removal of
// unreferenced blobs takes one this capture is about to list.
Result<store::Capture> StoreCaptureFolder(const store::Job& job, const fs::path& dir,
                                          const JobRunnerContext& context) {
  SOFTID_ASSIGN_OR_RETURN(const std::vector<std::string> files, ListFiles(dir));
  std::shared_lock<std::shared_mutex> puts;
  if (context.blob_puts != nullptr) puts = std::shared_lock(*context.blob_puts);
  std::vector<store::ManifestEntry> manifest;
  for (const std::string& path : files) {
    std::ifstream in(dir / path, std::ios::binary);
    if (!in) return Status::IoError("cannot read the ingested file " + path);
    SOFTID_ASSIGN_OR_RETURN(std::string sha256,
                            context.blobs->Put(in, store::PutOptions{.source_name = path}));
    std::error_code error;
    const auto size = fs::file_size(dir / path, error);
    if (error) return Status::IoError("cannot size the ingested file " + path);
    manifest.push_back({path, std::move(sha256), static_cast<int64_t>(size)});
  }
  return context.jobs->CreateCapture(manifest, "", job.owner, store::kCaptureFormat);
}

}  // namespace

Result<IngestedCapture> IngestRecording(const store::Job& job, const store::Capture& stored,
                                        const std::string& worker_id,
                                        const JobRunnerContext& context, const fs::path& work_dir,
                                        const std::atomic<bool>* cancel) {
  const fs::path recording_dir = work_dir / "recording";
  const fs::path capture_dir = work_dir / "ingested";
  auto shown = [&](const Status& status) {
    return Status(status.code(), RedactPath(RedactPath(status.message(), recording_dir),
                                            capture_dir, "<ingested>/"));
  };
  if (Status laid_out = MaterializeCapture(stored, *context.blobs, recording_dir); !laid_out.ok()) {
    return laid_out.WithContext("recording " + stored.id);
  }
  Result<recording::Recording> recording = recording::ReadRecording(recording_dir);
  if (!recording.ok()) return shown(recording.status()).WithContext("recording " + stored.id);

  IngestNotes notes(job, context);
  ingest::IngestOptions options;
  options.cancel = cancel;
  // The ingest keeps to the job's share of the cores, as the fit does.
  options.threads = context.cores_per_job;
  options.static_scene.threads = context.cores_per_job;
  options.registration.threads = context.cores_per_job;
  Result<ingest::IngestReport> report = ingest::Ingest(
      *recording, capture_dir, options,
      [&](std::string_view stage, int done, int total) { notes(stage, done, total); });
  if (!report.ok()) return shown(report.status());
  context.logger->info("job {}: ingested recording {}: {} frames, registration RMS {:.2g} m",
                       job.id, stored.id, report->frame_times_s.size(), report->registration.rms_m);

  Result<store::Capture> derived = StoreCaptureFolder(job, capture_dir, context);
  if (!derived.ok()) return derived.status().WithContext("storing the ingested capture");
  SOFTID_RETURN_IF_ERROR(context.jobs->SetDerivedCapture(job.id, worker_id, derived->id));
  store::ProgressEvent note;
  note.kind = store::ProgressKind::kState;
  note.message = "ingest: done, derived capture " + derived->id;
  (void)context.jobs->AppendProgress(job.id, note);
  context.events->Notify(job.id);
  // Neither layout is needed by the fit, which reads the stored capture's own (hard links to its
  // blobs): half the disk while it runs.
  std::error_code ignored;
  fs::remove_all(recording_dir, ignored);
  fs::remove_all(capture_dir, ignored);
  return IngestedCapture{*std::move(derived), report->ToJson()};
}

Result<IngestedCapture> LoadIngestedCapture(const store::Job& job,
                                            const JobRunnerContext& context) {
  SOFTID_ASSIGN_OR_RETURN(store::Capture derived, context.jobs->GetCapture(job.derived_capture_id));
  for (const store::ManifestEntry& entry : derived.manifest) {
    if (entry.path != kIngestReportFile) continue;
    SOFTID_ASSIGN_OR_RETURN(const std::string text, context.blobs->Get(entry.sha256));
    nlohmann::json report = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (report.is_discarded()) {
      return Status::Internal("capture " + derived.id + ": ingest.json is not JSON");
    }
    return IngestedCapture{std::move(derived), std::move(report)};
  }
  return Status::Internal("capture " + derived.id + ": has no ingest.json");
}

}  // namespace softid::server
