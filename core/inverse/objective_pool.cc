#include "core/inverse/objective_pool.h"

#include <algorithm>
#include <atomic>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

namespace softid::inverse {

Status RunOnObjectives(const ObjectiveFactory& make_objective, int num_tasks, int threads,
                       const std::function<Status(TrajectoryObjective&, int)>& task_fn) {
  if (num_tasks <= 0) return Status::Ok();
  std::atomic<int> next{0};
  std::mutex error_mutex;
  Status error;
  const auto fail = [&](Status status) {
    std::lock_guard lock(error_mutex);
    if (error.ok()) error = std::move(status);
  };
  const auto failed = [&] {
    std::lock_guard lock(error_mutex);
    return !error.ok();
  };
  auto worker = [&]() {
    std::unique_ptr<TrajectoryObjective> objective;
    try {
      objective = make_objective();
    } catch (const std::invalid_argument& e) {
      fail(Status::InvalidArgument(e.what()));
      return;
    }
    if (objective == nullptr) {
      fail(Status::Internal("the objective factory returned null"));
      return;
    }
    for (int task = next++; task < num_tasks && !failed(); task = next++) {
      if (Status done = task_fn(*objective, task); !done.ok()) {
        fail(std::move(done));
        return;
      }
    }
  };
  threads = std::clamp(threads, 1, num_tasks);
  {
    std::vector<std::jthread> pool;
    for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
    worker();
  }
  return error;
}

}  // namespace softid::inverse
