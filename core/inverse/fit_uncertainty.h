// How sure a fit is, for every result: the identifiability analysis at the best start
// (identifiability.h: Laplace approximation from the Hessian of the cost, correlations, named
// undetermined combinations), and each fitted parameter's 1-sigma in its own public form
// (a number, [x, y, z], the plane's normal and offset), propagated from the covariance of the
// optimiser's variables through the parameter space's transforms.
//
// The statistical uncertainty is the Laplace figure, widened where the residuals are correlated
// within and across frames (the model itself is off: identifiability.h, step 2b). The residual
// sigma has a floor at the capture's depth quantisation (depth_scale / sqrt(12)), so a noise-free
// synthetic fit does not claim zero uncertainty.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/inverse/discretisation_error.h"
#include "core/inverse/fit.h"
#include "core/inverse/identifiability.h"
#include "core/inverse/job_config.h"
#include "core/inverse/rest_frame_noise.h"  // DepthQuantisationSigma

namespace softid::inverse {

struct ParameterUncertainty {
  std::string name;  // the fitted name ("youngs_modulus", "ground_plane", ...)
  // One per number of the value's public JSON form, in its order (ParameterValueJson); +inf where
  // the data do not determine it.
  std::vector<double> standard_uncertainty;
};

struct FitUncertainty {
  IdentifiabilityReport report;
  std::vector<ParameterUncertainty> parameters;  // in the order of FitResult::fitted
  // The discretisation error of each fitted value (discretisation_error.h), or why it is missing.
  std::optional<DiscretisationError> discretisation;
  std::string discretisation_failure;
};

// The analysis of `fit` (its best start). Errors of the analysis (a simulation that diverges at a
// step of the difference stencil) are returned; callers report them next to the fit rather than
// failing it.
Result<FitUncertainty> EstimateFitUncertainty(const capture::Capture& capture,
                                              const JobConfig& config, const FitResult& fit);

// ToJson(fit) with "standard_uncertainty" (same shape as "value", null where infinite) and, for
// scalars, "relative_uncertainty" in each entry of "parameters", and the analysis under
// "uncertainty" (ToJson(IdentifiabilityReport)). With `uncertainty` null: ToJson(fit), plus
// "uncertainty": {"error": `error`} when `error` is not empty.
nlohmann::json ToJson(const FitResult& fit, const FitUncertainty* uncertainty,
                      const std::string& error = "");

}  // namespace softid::inverse
