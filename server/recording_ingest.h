// The first stage of a job on a raw recording (softid-recording/1): lays the recording out in the
// job's work folder, ingests it into a capture (core/ingest) with its stages recorded as notes in
// the job's history, stores that capture as an ordinary capture of the job's station (its blobs
// shared with any capture holding the same files) and records it as the job's derived capture.
// The derived capture keeps ingest.json among its files, so a retried job whose ingest had
// finished loads the capture and its report instead of ingesting again.
#pragma once

#include <atomic>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/common/status.h"
#include "server/job_runner.h"
#include "server/store/capture.h"
#include "server/store/job.h"

namespace softid::server {

struct IngestedCapture {
  store::Capture capture;  // the derived capture as stored
  nlohmann::json report;   // its ingest.json ("softid-ingest/1")
};

// Ingests `recording` (the job's capture) in `work_dir` (a private folder the caller removes)
// and stores the result for `job`, claimed by `worker_id`. Errors are the ingest's (they name
// the stage, the camera and the frame) with the work folder's paths removed; Cancelled once
// `cancel` is set (checked between frames), with nothing stored.
Result<IngestedCapture> IngestRecording(const store::Job& job, const store::Capture& recording,
                                        const std::string& worker_id,
                                        const JobRunnerContext& context,
                                        const std::filesystem::path& work_dir,
                                        const std::atomic<bool>* cancel = nullptr);

// The derived capture of a job whose ingest finished on an earlier attempt, with its report.
Result<IngestedCapture> LoadIngestedCapture(const store::Job& job, const JobRunnerContext& context);

}  // namespace softid::server
