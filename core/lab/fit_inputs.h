// The inputs of the lab's fitting commands (fit, diagnose): a capture folder (headers; frames are
// read by the fit) and an optional job config, with the lab's exit codes on failure.
#pragma once

#include <string>
#include <variant>

#include "core/capture/capture.h"
#include "core/inverse/job_config.h"

namespace softid::lab {

struct FitInputs {
  capture::Capture capture;
  inverse::JobConfig config;  // defaults when no config file is given
};

// Reads both, logging what is wrong. Returns the exit code instead when either cannot be read:
// kExitFailure for a missing capture, kExitInvalidInput for an invalid capture or config.
std::variant<FitInputs, int> LoadFitInputs(const std::string& capture_path,
                                           const std::string& config_path);

}  // namespace softid::lab
