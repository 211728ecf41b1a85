// One row of a job's progress history: an optimiser iteration, or a state change. The history is
// what a watcher streams (resuming from an iteration number) and, through `parameters`, the last
// known point a restarted job can resume from.
#pragma once

#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

#include "core/common/status.h"
#include "server/store/job.h"
#include "server/store/timestamp.h"

namespace softid::server::store {

enum class ProgressKind {
  kIteration,  // written by the worker after each optimiser iteration, only while RUNNING
  // Written by the store itself on every state transition (created, claimed, succeeded, ...).
  // A worker may add its own notes (e.g. "resumed from iteration 12") in any state; the store
  // stamps them with the job's current state.
  kState,
};

// "iteration" / "state": the spelling in the database.
const char* ToString(ProgressKind kind);
Result<ProgressKind> ProgressKindFromString(std::string_view text);

struct ProgressEvent {
  // Position in the job's history, 1, 2, 3, ... assigned by the store; ignored on append.
  int64_t seq = 0;
  // Which claim of the job wrote the event (Job::attempts at the time; 0 before the first claim).
  // Assigned by the store; ignored on append.
  int attempt = 0;
  ProgressKind kind = ProgressKind::kIteration;
  // For kIteration, the optimiser iteration (>= 0; a resumed attempt may repeat numbers). For
  // kState, the iteration of the job's latest iteration event (0 before any), assigned by the
  // store, so that listing "from iteration N" includes the state changes that happened since.
  int iteration = 0;
  double cost = std::nan("");           // objective value; NaN when not available
  double gradient_norm = std::nan("");  // |∇cost|; NaN when not available
  // Current parameter estimate (named material parameters), or null.
  nlohmann::json parameters = nullptr;
  double elapsed_s = 0.0;  // wall time since the attempt started, s
  // For kState, the job's state after the event (assigned by the store). Unused for kIteration.
  std::optional<JobState> state = std::nullopt;
  std::string message = "";  // a state change's reason (an error, "lease expired"); free text
  // For kIteration: which of the job's random starts reported it (0-based; each start numbers
  // its iterations from 0) and how many there are. 0 and 1 for kState.
  int start = 0;
  int num_starts = 1;
  // For kIteration: the fit's estimate of the time left for the whole job, s; NaN when unknown.
  double remaining_s = std::nan("");
  Timestamp created_at{};  // assigned by the store
};

}  // namespace softid::server::store
