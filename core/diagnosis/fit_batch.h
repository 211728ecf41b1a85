// How the diagnosis runs its refits: each refit is an independent fit of the same capture from a
// config of its own (one start each), so a batch of them can run anywhere, in any order, at once.
// The diagnosis hands every batch it can form (the candidates' refits, the joint refits, the base
// model refitted from the refits) to a FitBatchRunner and reads the results in the order of the
// configs. By default the batch runs here, its fits side by side on the cores (RunFitsInProcess);
// the server runs it as tasks that any worker claims (server/start_tasks.h). A runner must return
// what inverse::Fit(capture, config, options) returns for each config, so the diagnosis does not
// depend on where its refits ran.
#pragma once

#include <functional>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/inverse/fit.h"
#include "core/inverse/job_config.h"

namespace softid::diagnosis {

// One result per config, in the configs' order.
using FitBatchRunner = std::function<std::vector<Result<inverse::FitResult>>(
    const std::vector<inverse::JobConfig>& configs)>;

// inverse::Fit of each config, up to `workers` of them at once (>= 1; each fit takes the cores its
// config's threads say); after a cancel (options.cancel) the fits not yet begun report Cancelled
// without running. options' callbacks are called from one fit at a time.
std::vector<Result<inverse::FitResult>> RunFitsInProcess(
    const capture::Capture& capture, const std::vector<inverse::JobConfig>& configs,
    const inverse::FitOptions& options, int workers = 1);

}  // namespace softid::diagnosis
