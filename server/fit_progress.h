// A fit's progress lines as ITERATION events of its job's history, what watchers stream: the
// fitted values, start i of n, the continuation stage, unconverged steps. Written by the job's
// worker, and by the workers running its starts as tasks.
#pragma once

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

}  // namespace softid::server
