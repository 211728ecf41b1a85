#include "core/inverse/fit_checkpoint.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace softid::inverse {
namespace {

using Json = nlohmann::json;

// JSON has no NaN or infinity (a failed start's cost may be either): null stands for them.
Json Number(double value) {
  return std::isfinite(value) ? Json(value) : Json(nullptr);
}

double ReadNumber(const Json& value) {
  return value.is_null() ? std::numeric_limits<double>::quiet_NaN() : value.get<double>();
}

Json StageJson(const HorizonStageResult& stage) {
  return {{"last_frame", stage.last_frame},
          {"iterations", stage.iterations},
          {"initial_cost", Number(stage.initial_cost)},
          {"final_cost", Number(stage.final_cost)},
          {"termination", stage.termination}};
}

HorizonStageResult ReadStage(const Json& j) {
  return {j.at("last_frame").get<int>(), j.at("iterations").get<int>(),
          ReadNumber(j.at("initial_cost")), ReadNumber(j.at("final_cost")),
          j.at("termination").get<std::string>()};
}

Json RefinementJson(const RefinementResult& r) {
  return {{"iterations", r.iterations},
          {"initial_cost", Number(r.initial_cost)},
          {"final_cost", Number(r.final_cost)},
          {"converged", r.converged},
          {"termination", r.termination},
          {"evaluations", r.evaluations},
          {"failed_evaluations", r.failed_evaluations}};
}

RefinementResult ReadRefinement(const Json& j) {
  RefinementResult r;
  r.iterations = j.at("iterations").get<int>();
  r.initial_cost = ReadNumber(j.at("initial_cost"));
  r.final_cost = ReadNumber(j.at("final_cost"));
  r.converged = j.at("converged").get<bool>();
  r.termination = j.at("termination").get<std::string>();
  r.evaluations = j.at("evaluations").get<int>();
  r.failed_evaluations = j.at("failed_evaluations").get<int>();
  return r;
}

Json StartJson(const StartResult& s) {
  Json stages = Json::array();
  for (const HorizonStageResult& stage : s.stages) stages.push_back(StageJson(stage));
  Json history = Json::array();
  for (double cost : s.cost_history) history.push_back(Number(cost));
  return {{"index", s.index},
          {"initial", fem::ToJson(s.initial)},
          {"final", fem::ToJson(s.final)},
          {"initial_cost", Number(s.initial_cost)},
          {"final_cost", Number(s.final_cost)},
          {"initial_heldout_cost", Number(s.initial_heldout_cost)},
          {"final_heldout_cost", Number(s.final_heldout_cost)},
          {"iterations", s.iterations},
          {"converged", s.converged},
          {"termination", s.termination},
          {"failed", s.failed},
          {"stopped_at_time_limit", s.stopped_at_time_limit},
          {"cost_history", history},
          {"cost_history_last_frame", s.cost_history_last_frame},
          {"stages", stages},
          {"refinement", s.refinement ? RefinementJson(*s.refinement) : Json(nullptr)},
          {"flight", s.flight ? ToJson(*s.flight) : Json(nullptr)},
          {"evaluations", s.evaluations},
          {"failed_evaluations", s.failed_evaluations},
          {"seconds", s.seconds},
          {"forward_seconds", s.forward_seconds},
          {"backward_seconds", s.backward_seconds},
          {"steps", s.steps},
          {"unconverged_steps", s.unconverged_steps}};
}

Result<StartResult> ReadStart(const Json& j) {
  StartResult s;
  s.index = j.at("index").get<int>();
  SOFTID_ASSIGN_OR_RETURN(s.initial, fem::PhysicalParametersFromJson(j.at("initial")));
  SOFTID_ASSIGN_OR_RETURN(s.final, fem::PhysicalParametersFromJson(j.at("final")));
  s.initial_cost = ReadNumber(j.at("initial_cost"));
  s.final_cost = ReadNumber(j.at("final_cost"));
  s.initial_heldout_cost = ReadNumber(j.at("initial_heldout_cost"));
  s.final_heldout_cost = ReadNumber(j.at("final_heldout_cost"));
  s.iterations = j.at("iterations").get<int>();
  s.converged = j.at("converged").get<bool>();
  s.termination = j.at("termination").get<std::string>();
  s.failed = j.at("failed").get<bool>();
  s.stopped_at_time_limit = j.value("stopped_at_time_limit", false);
  for (const Json& cost : j.at("cost_history")) s.cost_history.push_back(ReadNumber(cost));
  s.cost_history_last_frame = j.at("cost_history_last_frame").get<std::vector<int>>();
  if (s.cost_history_last_frame.size() != s.cost_history.size()) {
    return Status::InvalidArgument(
        "cost_history_last_frame: " + std::to_string(s.cost_history_last_frame.size()) +
        " entries for " + std::to_string(s.cost_history.size()) + " costs");
  }
  for (const Json& stage : j.at("stages")) s.stages.push_back(ReadStage(stage));
  if (!j.at("refinement").is_null()) s.refinement = ReadRefinement(j.at("refinement"));
  // Absent from checkpoints written before the flight stage existed.
  if (j.contains("flight") && !j.at("flight").is_null()) {
    SOFTID_ASSIGN_OR_RETURN(s.flight, FlightStageResultFromJson(j.at("flight")));
  }
  s.evaluations = j.at("evaluations").get<int>();
  s.failed_evaluations = j.at("failed_evaluations").get<int>();
  s.seconds = j.at("seconds").get<double>();
  s.forward_seconds = j.at("forward_seconds").get<double>();
  s.backward_seconds = j.at("backward_seconds").get<double>();
  s.steps = j.at("steps").get<long long>();
  s.unconverged_steps = j.at("unconverged_steps").get<long long>();
  return s;
}

GridSelection ReadGridSelection(const Json& j) {
  GridSelection selection;
  selection.cells = j.at("cells").get<int>();
  selection.depth_noise_m = j.at("depth_noise_m").get<double>();
  selection.tolerance_m = j.at("tolerance_m").get<double>();
  selection.within_tolerance = j.at("within_tolerance").get<bool>();
  selection.stopped_at_time_limit = j.value("stopped_at_time_limit", false);  // older: absent
  selection.untried_cells = j.value("untried_cells", 0);
  selection.untried_grid_nodes = j.value("untried_grid_nodes", 0);
  for (const Json& t : j.at("trials")) {
    GridTrial trial;
    trial.cells = t.at("cells").get<int>();
    trial.finer_cells = t.at("finer_cells").get<int>();
    trial.grid_nodes = t.at("grid_nodes").get<int>();
    trial.difference_m = t.at("difference_m").get<double>();
    trial.worst_frame = t.at("worst_frame").get<int>();
    // Checkpoints written before this key existed still resume.
    trial.frames_within_tolerance = t.value("frames_within_tolerance", 0);
    trial.per_frame_m = t.value("per_frame_m", std::vector<double>{});
    trial.diverged = t.at("diverged").get<bool>();
    trial.seconds = t.at("seconds").get<double>();
    selection.trials.push_back(trial);
  }
  return selection;
}

SubstepSelection ReadSubstepSelection(const Json& j) {
  SubstepSelection selection;
  selection.substeps = j.at("substeps").get<int>();
  selection.tolerance_m = j.at("tolerance_m").get<double>();
  selection.within_tolerance = j.at("within_tolerance").get<bool>();
  // Checkpoints written before these keys existed still resume.
  selection.converging = j.value("converging", true);
  selection.stopped_at_time_limit = j.value("stopped_at_time_limit", false);
  selection.max_substeps = j.value("max_substeps", 16);  // the largest candidate before it was kept
  for (const Json& t : j.at("trials")) {
    SubstepTrial trial;
    trial.substeps = t.at("substeps").get<int>();
    trial.difference_m = t.at("difference_m").get<double>();
    trial.worst_frame = t.at("worst_frame").get<int>();
    trial.frames_within_tolerance = t.value("frames_within_tolerance", 0);
    trial.frames_converging = t.value("frames_converging", trial.frames_within_tolerance);
    trial.per_frame_m = t.value("per_frame_m", std::vector<double>{});
    trial.diverged = t.at("diverged").get<bool>();
    selection.trials.push_back(trial);
  }
  return selection;
}

Result<FitCheckpoint> ReadCheckpoint(const Json& j) {
  FitCheckpoint checkpoint;
  checkpoint.num_starts = j.at("num_starts").get<int>();
  if (checkpoint.num_starts < 1) {
    return Status::InvalidArgument(
        "checkpoint: num_starts = " + std::to_string(checkpoint.num_starts) + " (must be >= 1)");
  }
  const Json& grid = j.at("grid");
  checkpoint.cells = grid.at("cells").get<int>();
  checkpoint.cell_size_m = grid.at("cell_size_m").get<double>();
  if (grid.contains("selection")) checkpoint.grid_selection = ReadGridSelection(grid["selection"]);
  const Json& time_step = j.at("time_step");
  checkpoint.substeps = time_step.at("substeps").get<int>();
  if (time_step.contains("selection")) {
    checkpoint.substep_selection = ReadSubstepSelection(time_step["selection"]);
  }
  if (!(checkpoint.cell_size_m > 0.0) || checkpoint.substeps < 1) {
    return Status::InvalidArgument(
        "checkpoint: grid.cell_size_m = " + std::to_string(checkpoint.cell_size_m) +
        ", time_step.substeps = " + std::to_string(checkpoint.substeps) +
        " (must be > 0 and >= 1)");
  }
  for (const Json& start : j.at("finished")) {
    Result<StartResult> read = ReadStart(start);
    if (!read.ok()) return read.status().WithContext("checkpoint: finished start");
    if (read->index < 0 || read->index >= checkpoint.num_starts ||
        checkpoint.IsFinished(read->index)) {
      return Status::InvalidArgument("checkpoint: finished start index " +
                                     std::to_string(read->index) + " is out of range or repeated");
    }
    checkpoint.finished.push_back(std::move(read).value());
  }
  return checkpoint;
}

}  // namespace

nlohmann::json StartCheckpointJson(const StartResult& start) {
  return StartJson(start);
}

Result<StartResult> StartFromCheckpointJson(const nlohmann::json& json) {
  try {
    return ReadStart(json);
  } catch (const nlohmann::json::exception& e) {
    return Status::InvalidArgument(std::string("start: ") + e.what());
  }
}

bool FitCheckpoint::IsFinished(int start_index) const {
  return std::any_of(finished.begin(), finished.end(),
                     [&](const StartResult& s) { return s.index == start_index; });
}

nlohmann::json ToJson(const FitCheckpoint& checkpoint) {
  Json grid = {{"cells", checkpoint.cells}, {"cell_size_m", checkpoint.cell_size_m}};
  if (checkpoint.grid_selection) grid["selection"] = ToJson(*checkpoint.grid_selection);
  Json time_step = {{"substeps", checkpoint.substeps}};
  if (checkpoint.substep_selection) time_step["selection"] = ToJson(*checkpoint.substep_selection);
  Json finished = Json::array();
  for (const StartResult& start : checkpoint.finished) finished.push_back(StartJson(start));
  return {{"format", FitCheckpoint::kFormat},
          {"num_starts", checkpoint.num_starts},
          {"grid", grid},
          {"time_step", time_step},
          {"finished", finished}};
}

Result<FitCheckpoint> FitCheckpointFromJson(const nlohmann::json& json) {
  try {
    if (!json.is_object() || !json.contains("format") || json["format"] != FitCheckpoint::kFormat) {
      return Status::InvalidArgument(std::string("checkpoint: format is not ") +
                                     FitCheckpoint::kFormat);
    }
    return ReadCheckpoint(json);
  } catch (const nlohmann::json::exception& e) {
    // A missing key or a value of the wrong type: the library's message names it.
    return Status::InvalidArgument(std::string("checkpoint: ") + e.what());
  }
}

}  // namespace softid::inverse
