// Diagnosis of left-out physics: fit the base model, locate where and when it misses
// the recording, screen the candidate extensions, refit the best with every base parameter free,
// and decide with the pre-registered rule (decision.h).
//
//   Diagnose(capture, config, options) -> DiagnosisReport, with ToJson (diagnosis.json) and
//   ToText in report.h. Callers that honour a job config's "diagnose": true (softid-lab fit,
//   softid-lab diagnose, the service) call Diagnose instead of, or after, inverse::Fit; Fit itself
//   ignores the key.
//
// Cost: the base fit, one adjoint and ~20 forward runs of screening, max_refits fits, and the
// identifiability analysis (2 adjoint runs per fitted variable) of the final model, all on the
// comparison discretisation (DiagnoseOptions::comparison_cells), then one fit of the final model on
// the job's when that is finer, within what is left of DiagnoseOptions::max_seconds. A capture
// whose base fit is at the noise floor stops after the base fit and its identifiability (and that
// refit).
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/diagnosis/decision.h"
#include "core/diagnosis/fit_batch.h"
#include "core/diagnosis/localization.h"
#include "core/diagnosis/motion_phases.h"
#include "core/diagnosis/noise_floor.h"
#include "core/diagnosis/screening.h"
#include "core/diagnosis/time_step_error.h"
#include "core/inverse/fit.h"
#include "core/inverse/job_config.h"

namespace softid::diagnosis {

struct DiagnoseOptions {
  NoiseFloorOptions noise_floor;
  MotionPhaseOptions phases;
  ScreeningOptions screening;
  DecisionOptions decision;
  // Surface patches of the residual map [-], >= 1. 8: the corners of a box-like body, coarse
  // enough for ~50 points each per frame at the usual resolutions.
  int patches = 8;
  // Held-out frames when the job holds none out (every k-th frame) [-], >= 2: the decision rule
  // needs frames the fits did not see.
  int default_heldout_every = 4;
  // Restarts from a better base fit [-], >= 0: when nothing explains the misfit, the base model
  // refitted from the refits' values may land far lower (the first base fit stopped in a local
  // minimum); the diagnosis then runs again from that base. 1: one restart at most.
  int max_base_restarts = 1;
  // Run the identifiability analysis of the final model (2 adjoint runs per fitted variable).
  bool identifiability = true;
  // The grid (cells along the longest side) and time step (substeps per frame) the models are
  // compared on, at most [-], >= 0; 0 = the job's own. Comparing models needs one discretisation
  // for all of them, not a converged one, and a fit's "auto" choice on a contact-rich capture
  // (16 cells x 16 substeps on a cube sliding down a ramp) makes each of the diagnosis' few
  // hundred simulations ~16x dearer than 10 x 4, which is what the concealed-effect benchmark runs
  // (softid-lab prove-diagnosis: 6 of 6 effects named, 0 of 21 false alarms). When the job's
  // discretisation is finer (or "auto"), the final model is refitted at the job's own from the
  // compared optimum, and that fit is the report's final_fit.
  int comparison_cells = 10;
  int comparison_substeps = 4;
  // Leave the compared time step's own error out of the base misfit before the phases and
  // patches are judged (time_step_error.h): the base model once more at half the step, and once
  // per base variable for its sensitivities. true: a block landing on a corner, compared at 4
  // substeps per frame, misses a CalculiX capture by 3-10x the noise on impact, where halving
  // the step moves its surface as much; flagging that misfit blames the recording for the
  // comparison's step.
  bool remove_time_step_error = true;
  // The diagnosis' wall-time budget [s], >= 0; 0 = none. Only the final refit at the job's
  // discretisation gives way to it: its optimisation stops at its first iteration that ends past
  // the budget (SolverOptions::max_seconds) and keeps its best point, and the report says so;
  // when the comparison has spent the budget it is not started (its grid and time-step checks
  // alone took 6 minutes on a CalculiX block, for no iteration). The comparison is not cut short
  // (the decision needs every stage). 600: a one-second, one-camera capture diagnosed on 2 cores
  // within about 10 minutes; past it, the final values lie between the compared optimum and the
  // job's, and a fit of the found model gives the rest.
  double max_seconds = 600.0;
  // Folder for the PNG plots; empty = no plots.
  std::filesystem::path plot_directory;
  // Stage messages ("base fit", "screening", ...), and the fits' progress and cancellation.
  std::function<void(const std::string&)> on_stage;
  inverse::FitOptions fit;
  // Runs each batch of refits (fit_batch.h); empty = here, one after the other, with `fit`.
  FitBatchRunner run_fits;
  Status Validate() const;
};

// One refitted candidate: against the base, or (test.conditional) jointly with an accepted
// nuisance against the nuisance's refit (decision.h, step 2).
struct TestedCandidate {
  CandidateTest test;
  nlohmann::json values;  // ExtensionValues of the refit
  // Per optimiser variable of the extension: standard uncertainty from the identifiability
  // analysis (Hessian of the cost), null when unbounded or not run.
  nlohmann::json uncertainty;
  // The profile check of the found value (decision gate e): {"change", "lr_minus", "lr_plus",
  // "determined", "relative_uncertainty"}; null when not run.
  nlohmann::json profile;
  nlohmann::json fit;  // result.json of the refit
  Localization after;  // residuals of the refit, normalised by the base noise floor
  fem::PhysicalParameters parameters;
  // The null model's parameters the test compares with (the base fit's, the nuisance's refit's,
  // or the null refitted from this refit when that went lower): gate f runs them again.
  fem::PhysicalParameters before_parameters;
  std::vector<double> cost_history;  // initial cost, then after each iteration [m^2]
  // Each start of the refit: {"start": values, "found": values, "cost"} (or "error"); a
  // two-sided variable is refitted from both sides of its null, the lowest cost is kept.
  nlohmann::json starts = nlohmann::json::array();
  // A conditional test (test.conditional): the nuisance's values in the joint refit.
  nlohmann::json nuisance_values;
  // When the refit passed gates a-d: the null model refitted from the refit's values with the
  // extension at its null, {"cost", "heldout", "replaced_null"} (or {"error"}); a lower cost
  // replaces the null's (cost_before, heldout_before, LR) and the gates are applied again.
  nlohmann::json null_refit;
  // The refit's free parameters (the base model's and the extension's; with a nuisance's too).
  std::vector<std::string> fitted;
  // That null refit itself, when it fitted the base model's parameters only (a base restart then
  // reuses it instead of fitting the same start again).
  std::optional<inverse::FitResult> null_fit;
};

struct DiagnosisReport {
  std::string decision;  // "friction" | "heterogeneous_stiffness" | "air_drag" | "none" |
                         // "unexplained" (a nuisance, the contact law too, is never the decision)
  int winner = -1;       // index into `tested` of the deciding test, -1 when none decided
  NoiseFloor noise_floor;
  std::vector<FrameMotion> motion;  // per observed frame, at the base fit
  std::vector<int> frames;          // capture frame indices
  std::vector<bool> heldout;
  Localization before;                         // base fit
  Localization after;                          // final model (= before when nothing was accepted)
  double base_cost = 0.0, base_heldout = 0.0;  // [m^2]
  double n_eff = 0.0;                          // of the base residuals
  std::vector<ScreenedCandidate> screening;
  std::vector<TestedCandidate> tested;
  nlohmann::json nuisances = nlohmann::json::array();
  nlohmann::json base_fit, final_fit;  // result.json
  // The discretisation the models were compared on, {"cells", "substeps"}, and when the final
  // model was then refitted at the job's own (DiagnoseOptions::comparison_cells), that refit's
  // {"cells", "substeps", "seconds"} as "final_refit"; final_fit is then that refit.
  nlohmann::json compared_at;
  // The compared time step's own error, left out of the base misfit (null when
  // DiagnoseOptions::remove_time_step_error is off or the run at half the step failed).
  std::optional<TimeStepError> time_step_error;
  // The winner's extension values in that final refit (null without one): the finding's values.
  nlohmann::json final_values;
  // Earlier base fits left because a refit showed a lower null (DiagnoseOptions::
  // max_base_restarts): {"reason", "via", "cost_before", "cost_after", "first_decision",
  // "first_report" (the diagnosis.json of that base)}, oldest first.
  nlohmann::json base_restarts = nlohmann::json::array();
  nlohmann::json identifiability;  // of the final model, or null
  std::vector<std::string> plots;
  double seconds = 0.0;
  double screening_seconds = 0.0;  // of `seconds`: the screening's forward and adjoint runs
};

// Runs the diagnosis. The config's fit set is the base model; heldout_every 0 is replaced by
// options.default_heldout_every; config.diagnose is ignored.
// @param base_fit optional: the finished fit of `capture` under `config` (a caller that has just
//   run it, like the service); used as the base model when config.heldout_every > 0 and it ran on
//   the comparison discretisation, otherwise the base is refitted (the decision needs frames the
//   fits did not see, and models compared on one discretisation). When the final model is the
//   base model, it is the final fit (instead of a refit on the job's discretisation).
// Errors: InvalidArgument for invalid options or a config that does not fit the capture (as
// inverse::Fit), FailedPrecondition when the base fit fails.
Result<DiagnosisReport> Diagnose(const capture::Capture& capture, const inverse::JobConfig& config,
                                 const DiagnoseOptions& options = {},
                                 const inverse::FitResult* base_fit = nullptr);

}  // namespace softid::diagnosis
