// The job configuration: the job's specification (which material parameters an identification
// job fits, where the fit starts, what stays fixed, which frames, and the reports asked for) and,
// in JobConfig::solver, how the fit is computed (SolverOptions: the simulation's grid and time
// step, the starts, the optimiser and the cost; solver_options.h). Parsed and typed once at the
// edge (JobConfigFromJson); everything downstream takes the typed struct.
//
// The JSON form is a public contract that capture stations and the gRPC service send; every key is
// optional (defaults below), unknown keys are rejected by name:
//   {
//     "fit": ["youngs_modulus", "poisson_ratio"],   // unique fittable names (fem::ParameterInfo);
//                                                   // "ground" is an alias of "ground_plane"
//     "initial": {                                  // start values of fitted parameters only
//       "youngs_modulus": {"min": 1e4, "max": 1e6}, // scalars: a range for random starts ...
//       "poisson_ratio": 0.35,                      // ... or one value in the public JSON form
//       "ground_plane": {"normal": [0, 0.2, 1], "offset": 0.0}  // any non-zero normal
//     },
//     "fixed": {"density": 950, "gravity": [0, 0, -9.81]},  // PhysicalParameters public keys
//     "cells": "auto",           // cells along the longest side of the mesh, >= 2, or "auto"
//                                // (refinement until the surface moves less than the noise)
//     "cell_size": 0.005,        // [m] > 0; overrides "cells" when present
//     "substeps": "auto",        // steps per camera frame, >= 1, or "auto" (step doubling)
//     "rho_infinity": 0.8,       // generalized-alpha time stepping with this high-frequency
//                                // spectral radius in [0, 1]; absent: Newmark (gamma 0.6)
//     "frames": {"first": 0, "last": -1},  // capture frames fitted; last -1 = the capture's last
//     "heldout_every": 0,        // every k-th frame is held out for validation; 0 = none
//     "starts": 4, "threads": 0, "seed": 1,
//     "max_iterations": 50, "function_tolerance": 1e-6, "gradient_tolerance": 1e-10,
//     "parameter_tolerance": 1e-8,
//     "max_seconds": 0,          // wall time of the fit [s]; 0 = no limit
//     "gradient": "adjoint",     // or "finite_difference"
//     "finite_difference_step": 1e-4,
//     "continuation": true,      // fit a growing prefix of the frames first (fit.h)
//     "launch_from_flight": true,  // fit the launch on the frames before landing, then hold it
//     "predictable_frames_only": true,  // leave out frames after the motion turns chaotic
//     "refine_iterations": 0,    // Levenberg-Marquardt iterations after L-BFGS; 0 = none
//     "cost": {"band_cells": 3, "truncation_cells": 2.0,
//              "rest_sdf": "surface_fitted",  // or "exact", "sampled"
//              "frame_loss": "squared",       // or "cauchy" (frame_loss.h)
//              "frame_loss_noise_multiple": 2.0},
//     "diagnose": false, "uncertainty": true,
//     "refine_grid": false       // refit on a finer grid where it moves a value
//     (grid_refinement.h)
//   }
// Malformed input is rejected with InvalidArgument "<field path> = <value>: <reason>", e.g.
//   fit[1] = "youngs_modulo": unknown parameter (known: youngs_modulus, poisson_ratio, ...)
//   initial.poisson_ratio = 0.7: must lie in (0, 0.5)
// and unknown keys with "job config: unknown key \"fits\"" (or "frames: ...", "cost: ...", and
// "initial.<name>: ..." inside a range). Parameter values follow the rules of
// fem::PhysicalParameters::Validate and fem::PhysicalParametersFromJson.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "core/fem/parameter_registry.h"
#include "core/fem/physical_parameters.h"
#include "core/inverse/solver_options.h"

namespace softid::inverse {

// The parameters a job can fit are those of fem::ParameterRegistry(), under their `name`; the
// PhysicalParameters key "ground" is an alias of "ground_plane".

// Whether `name` is a fittable name (canonical names only: not the alias "ground").
bool IsFittable(std::string_view name);
// The canonical fittable name of `name` ("ground" -> "ground_plane"), or nullopt when `name` is
// neither a fittable name nor an alias of one.
std::optional<std::string_view> CanonicalFittableName(std::string_view name);
// The PhysicalParameters public key of a fittable name ("ground_plane" -> "ground"; others are
// unchanged). Throws std::invalid_argument for a name that is not fittable.
std::string_view PhysicalParameterKey(std::string_view fittable_name);

using ParameterShape = fem::ParameterShape;
// Shape of a fittable name (or the alias "ground"); throws std::invalid_argument otherwise.
ParameterShape ShapeOf(std::string_view fittable_name);

// A range of start values of a scalar parameter; random starts are drawn from it.
struct ScalarRange {
  double min = 0.0;  // both valid values of the parameter, min < max
  double max = 0.0;
  friend bool operator==(const ScalarRange&, const ScalarRange&) = default;
};

// The start of one fitted parameter: exactly one of `value` and `range` is set.
struct InitialValue {
  // The value in its public JSON form, normalised as fem::ToJson writes it: numbers are doubles,
  // the ground normal has unit length, the stiffness field is in canonical form.
  std::optional<nlohmann::json> value;
  std::optional<ScalarRange> range;  // scalar parameters only
  friend bool operator==(const InitialValue&, const InitialValue&) = default;
};

// The capture frames a job fits (indices into the capture, both inclusive).
struct FrameRange {
  int first = 0;  // >= 0
  int last = -1;  // -1: the capture's last frame; otherwise >= first
  friend bool operator==(const FrameRange&, const FrameRange&) = default;
};

struct JobConfig {
  // Parameters to optimise: unique canonical fittable names (the alias "ground" is resolved to
  // "ground_plane" when parsing JSON), at least one.
  std::vector<std::string> fit = {"youngs_modulus"};
  // Start values of fitted parameters, keyed by canonical fittable name; every key is in `fit`.
  // Fitted parameters without an entry start from the base parameters (ApplyToParameters).
  std::map<std::string, InitialValue> initial;
  // Values of parameters held fixed, as a PhysicalParameters JSON object (public keys, "ground"
  // not "ground_plane"; "ground": null is free flight), normalised like InitialValue::value. No
  // key names a fitted parameter. Parameters neither fitted nor fixed keep the base values.
  nlohmann::json fixed = nlohmann::json::object();

  // Every k-th fitted frame (frames.first + k - 1, frames.first + 2k - 1, ...) is held out of the
  // fit and only reported, to validate the result on data it did not see. 0 = none; 1 is
  // rejected because it would hold out every frame.
  int heldout_every = 0;  // [-], 0 or >= 2
  FrameRange frames;      // all frames by default

  // How the fit is computed: grid, time step, starts, optimiser, cost (solver_options.h).
  SolverOptions solver;

  // Run the diagnosis of left-out physics after the fit and return its report with the result.
  // Honoured by the callers (softid-lab fit/diagnose, the service), which call
  // diagnosis::Diagnose; inverse::Fit itself ignores it.
  bool diagnose = false;
  // Estimate each fitted value's uncertainty after the fit (fit_uncertainty.h; 2 forward and
  // adjoint runs per fitted variable). Honoured by the callers that write results, like diagnose.
  bool uncertainty = true;
  // After the analysis, refit on the next finer grid when a fitted value's grid error exceeds
  // what the data resolve (grid_refinement.h). Needs `uncertainty`. Honoured by the same callers.
  bool refine_grid = false;

  // Whether `fittable_name` (canonical) is in `fit`.
  bool IsFitted(std::string_view fittable_name) const;
  // Whether capture frame `frame` is held out of the fit (see heldout_every).
  bool IsHeldOut(int frame) const;

  // Checks everything JobConfigFromJson checks, for configs built in code too, plus that names
  // are canonical ("ground_plane" in fit/initial, "ground" in fixed) and that every InitialValue
  // has exactly one of value and range. The first problem is named like the JSON errors.
  Status Validate() const;

  friend bool operator==(const JobConfig&, const JobConfig&) = default;
};

// Parses and validates a job config JSON object (see the top of this file). Aliases are resolved,
// values normalised. Errors are InvalidArgument "<field path> = <value>: <reason>".
Result<JobConfig> JobConfigFromJson(const nlohmann::json& json);
// Parses JSON text with JobConfigFromJson; errors are InvalidArgument "<source>: ...", JSON syntax
// errors "<source>: invalid JSON: parse error at line L, column C: ...".
Result<JobConfig> JobConfigFromString(std::string_view text, std::string_view source);
// Reads a job config file with JobConfigFromString. NotFound "<file>: job config not found" when
// the file does not exist; IoError when it cannot be read.
Result<JobConfig> ReadJobConfig(const std::filesystem::path& file);

// The JSON form with every key written out (cell_size only when > 0). Round-trips:
// JobConfigFromJson(ToJson(c)) == c for every config JobConfigFromJson returns.
nlohmann::json ToJson(const JobConfig& config);

// The starting parameters of a job: `base` (e.g. the scene's or the capture's defaults) with
// config.fixed and the plain initial values applied. Ranged parameters keep the base value (the
// caller draws starts from the range). InvalidArgument when the config or base is invalid, or
// when ground_plane is fitted but neither the initial values nor base give a ground plane.
Result<fem::PhysicalParameters> ApplyToParameters(const JobConfig& config,
                                                  const fem::PhysicalParameters& base);

}  // namespace softid::inverse
