#include "core/lab/fit_inputs.h"

#include <spdlog/spdlog.h>

#include "core/lab/commands.h"

namespace softid::lab {

std::variant<FitInputs, int> LoadFitInputs(const std::string& capture_path,
                                           const std::string& config_path) {
  Result<capture::Capture> capture =
      capture::ReadCapture(capture_path, capture::ReadCaptureOptions{.decode_frames = false});
  if (!capture.ok()) {
    spdlog::error("{}", capture.status().message());
    return capture.status().code() == StatusCode::kNotFound ? kExitFailure : kExitInvalidInput;
  }
  FitInputs inputs{std::move(capture).value(), inverse::JobConfig()};
  if (!config_path.empty()) {
    Result<inverse::JobConfig> read = inverse::ReadJobConfig(config_path);
    if (!read.ok()) {
      spdlog::error("{}", read.status().message());
      return kExitInvalidInput;
    }
    inputs.config = *read;
  }
  return inputs;
}

}  // namespace softid::lab
