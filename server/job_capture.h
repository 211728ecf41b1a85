// The capture a job fits, laid out in a private folder and read: the job's own capture, or for a
// raw recording the capture its ingest derives (ingested now, or on an earlier attempt).
#pragma once

#include <atomic>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "server/job_runner.h"
#include "server/store/capture.h"
#include "server/store/job.h"

namespace softid::server {

// Lays out and reads the capture `job` fits (`stored` is the job's capture) in `dir`. A recording
// is ingested when the job has no derived capture yet (which needs `worker_id` to hold the job),
// its report going to `ingest_report`. Errors say which capture or stage failed.
Result<capture::Capture> PrepareCapture(const store::Job& job, const store::Capture& stored,
                                        const std::string& worker_id,
                                        const JobRunnerContext& context,
                                        const std::filesystem::path& dir,
                                        const std::atomic<bool>& cancel,
                                        nlohmann::json* ingest_report);

}  // namespace softid::server
