#include "core/diagnosis/fit_batch.h"

namespace softid::diagnosis {

std::vector<Result<inverse::FitResult>> RunFitsInProcess(
    const capture::Capture& capture, const std::vector<inverse::JobConfig>& configs,
    const inverse::FitOptions& options) {
  std::vector<Result<inverse::FitResult>> results;
  results.reserve(configs.size());
  for (const inverse::JobConfig& config : configs) {
    if (options.cancel != nullptr && options.cancel->load()) {
      results.push_back(Status::Cancelled("the diagnosis was cancelled"));
      continue;
    }
    results.push_back(inverse::Fit(capture, config, options));
  }
  return results;
}

}  // namespace softid::diagnosis
