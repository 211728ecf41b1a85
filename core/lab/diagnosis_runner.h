// Shared by the lab's diagnosis commands (diagnose, fit with "diagnose": true, prove-diagnosis):
// diagnosis options with progress on the lab's log.
#pragma once

#include "core/diagnosis/diagnose.h"
#include "core/inverse/job_config.h"

namespace softid::lab {

// Default diagnosis options whose stage messages and fit progress go to spdlog (fit progress at
// debug level: a diagnosis runs several fits).
diagnosis::DiagnoseOptions DiagnoseOptionsForLab(const inverse::JobConfig& config,
                                                 const std::string& prefix = "");

}  // namespace softid::lab
