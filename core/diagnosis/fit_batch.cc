#include "core/diagnosis/fit_batch.h"

#include <algorithm>
#include <mutex>

#include "core/common/for_each_index.h"

namespace softid::diagnosis {

std::vector<Result<inverse::FitResult>> RunFitsInProcess(
    const capture::Capture& capture, const std::vector<inverse::JobConfig>& configs,
    const inverse::FitOptions& options, int workers) {
  std::vector<Result<inverse::FitResult>> results(configs.size(),
                                                  Status::Cancelled("the diagnosis was cancelled"));
  // The caller's callbacks see one fit at a time, as when the fits ran one after the other.
  std::mutex callback_mutex;
  inverse::FitOptions serialised = options;
  if (options.on_progress) {
    serialised.on_progress = [&](const inverse::FitProgress& progress) {
      std::lock_guard lock(callback_mutex);
      options.on_progress(progress);
    };
  }
  if (options.on_checkpoint) {
    serialised.on_checkpoint = [&](const inverse::FitCheckpoint& checkpoint) {
      std::lock_guard lock(callback_mutex);
      options.on_checkpoint(checkpoint);
    };
  }
  ForEachIndex(configs.size(), std::max(1, workers), [&](size_t i) {
    if (options.cancel != nullptr && options.cancel->load()) return;
    results[i] = inverse::Fit(capture, configs[i], serialised);
  });
  return results;
}

}  // namespace softid::diagnosis
