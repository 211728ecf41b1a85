// A fit's progress lines as ITERATION events of its job's history, what watchers stream: the
// fitted values, start i of n, the continuation stage, unconverged steps. Written by the job's
// worker, and by the workers running its starts as tasks.
#pragma once

#include <string>

#include "core/inverse/fit.h"
#include "core/inverse/job_config.h"
#include "server/job_runner.h"
#include "server/store/job.h"
#include "server/store/progress_event.h"

namespace softid::server {

// `elapsed_s`: seconds since the job's attempt began.
store::ProgressEvent IterationEvent(const inverse::FitProgress& progress,
                                    const inverse::JobConfig& config, double elapsed_s);

// Appends `event` to the job's history, wakes its watchers and counts the iteration; a failure
// to record it is logged, not returned (the fit goes on).
void RecordIteration(const store::Job& job, const store::ProgressEvent& event,
                     const JobRunnerContext& context);

// A note in the job's history (a kState event that changes nothing), pushed to watchers.
void RecordNote(const store::Job& job, const std::string& note, const JobRunnerContext& context);

// "resumed from a checkpoint: k of n starts finished on an earlier attempt" (none when k = 0).
void NoteKeptStarts(const store::Job& job, size_t kept, int num_starts,
                    const JobRunnerContext& context);

}  // namespace softid::server
