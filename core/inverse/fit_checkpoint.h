// What an interrupted fit needs to go on where it stopped (a worker lost mid-job, a server
// restarted): the grid and time step it chose and every start that finished. Fit() hands one to
// FitOptions::on_checkpoint once the discretisation is chosen and after each start; given back as
// FitOptions::resume_from, the fit chooses nothing again and runs only the starts still missing.
// Its result is the one the uninterrupted fit would have had: a start's path depends only on its
// starting point, the capture and the config.
//
// The start is the unit: a start stopped midway runs again from its beginning, because Ceres'
// L-BFGS cannot take its curvature memory back, and a restart from the last iterate with an
// empty memory would take another path than the uninterrupted fit.
//
// JSON (the service stores it between attempts; doubles round-trip exactly):
//   {"format": "softid-fit-checkpoint/1", "num_starts": 8,
//    "grid": {"cells": 16, "cell_size_m": .., "selection": {..}?},
//    "time_step": {"substeps": 4, "selection": {..}?},
//    "finished": [{"index": 3, "initial": {..}, "final": {..}, "cost": {..}, ...}, ..]}
// Start parameters are written whole (fem::ToJson), so a start reads back exactly as it was.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "core/common/status.h"
#include "core/inverse/fit.h"

namespace softid::inverse {

struct FitCheckpoint {
  static constexpr const char* kFormat = "softid-fit-checkpoint/1";

  int num_starts = 0;  // of the whole fit; a checkpoint of another config does not match
  // The discretisation chosen (FitResult's fields of the same names).
  int cells = 0;
  double cell_size_m = 0.0;
  std::optional<GridSelection> grid_selection;
  int substeps = 0;
  std::optional<SubstepSelection> substep_selection;
  // Starts that ran to their end (failed ones too: they would fail again), in finishing order.
  std::vector<StartResult> finished;

  bool IsFinished(int start_index) const;
};

nlohmann::json ToJson(const FitCheckpoint& checkpoint);
// InvalidArgument naming the field for a malformed checkpoint or another format.
Result<FitCheckpoint> FitCheckpointFromJson(const nlohmann::json& json);

// One finished start as a checkpoint lists it (every field, parameters whole), for a start run
// apart from the rest of its fit (FitOptions::only_starts) and combined later.
nlohmann::json StartCheckpointJson(const StartResult& start);
// InvalidArgument naming the field for a malformed start.
Result<StartResult> StartFromCheckpointJson(const nlohmann::json& json);

// The first part of a fit, apart: loads what the config fits and chooses the grid and time step
// when "auto", as Fit does. Its checkpoint (no start finished) lets starts run anywhere with the
// same discretisation (FitOptions::resume_from with only_starts). Errors as Fit's.
Result<FitCheckpoint> PrepareFit(const capture::Capture& capture, const JobConfig& config,
                                 const std::atomic<bool>* cancel = nullptr);

}  // namespace softid::inverse
