// Independent evaluations of one objective, spread over worker threads: each worker builds a
// TrajectoryObjective of its own (an objective holds a simulator and is not thread-safe).
#pragma once

#include <functional>
#include <memory>

#include "core/common/status.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::inverse {

// Builds a fresh objective; called once per worker thread.
using ObjectiveFactory = std::function<std::unique_ptr<TrajectoryObjective>()>;

// Runs task_fn(objective, task) for tasks 0..num_tasks-1 on up to `threads` workers (this thread
// among them), each with an objective from make_objective, each taking the next task. The first
// error stops the others and is returned; a factory that throws std::invalid_argument or returns
// null is an error too.
Status RunOnObjectives(const ObjectiveFactory& make_objective, int num_tasks, int threads,
                       const std::function<Status(TrajectoryObjective&, int)>& task_fn);

}  // namespace softid::inverse
