// Which fitted parameters, or combinations of them, the data determine at an optimum of the fit.
//
// Method (a Laplace approximation around the optimum x* in the optimiser's variables x; see
// parameter_space.h: log for positive quantities, so their uncertainties are relative):
//  1. H = d^2 C / dx^2 [m^2] by central differences of the adjoint gradient,
//       H e_j ~ (g(x* + s e_j) - g(x* - s e_j)) / (2 s),   symmetrised: H <- (H + H^T) / 2,
//     2p forward+adjoint runs for p variables, spread over worker threads (one TrajectoryObjective
//     each: objectives are not thread-safe).
//  2. Noise scale. The cost is a mean over N_eff observed points of rho(phi) ~ phi^2 / 2 (the
//     Tukey loss is quadratic near 0), so with independent residuals of variance sigma^2,
//       -log likelihood = N_eff C / sigma^2 + const,   sigma^2 ~ 2 C_min N_eff / (N_eff - p),
//     and the Laplace approximation of the posterior covariance is
//       Cov(x) = (sigma^2 / (2 N_eff)) (H / 2)^-1 = sigma^2 / N_eff * H^-1
//              = 2 C_min / (N_eff - p) * H^-1.
//     With the Cauchy frame loss (frame_loss.h) C_min is the reweighted least-squares cost (each
//     frame's cost times its weight) and H the loss's curvature: the covariance of least squares
//     weighted by the frames' weights, whatever their common scale.
//     N_eff defaults to the number of observed points in the fitted frames. Depth pixels are not
//     independent where the model itself is off (discretisation, left-out physics: neighbouring
//     residuals share the error), so these uncertainties are lower bounds (2b widens them); the
//     scale-free flags below (correlation, degenerate combinations) do not depend on sigma.
//  2b. With the Gauss-Newton curvature, whose residual Jacobian is at hand: each variable's
//     variance is widened to the frame-correlated (sandwich) estimate of correlated_residuals.h
//     where that is larger, Cov <- D Cov D with D = diag(max(1, sigma_sandwich / sigma_laplace)),
//     which keeps the Laplace correlations. Measured on independent CalculiX captures (see
//     docs/benchmarks.md).
//  3. Degenerate combinations: the eigen-decomposition of the unit-diagonal Hessian
//       H~ = D^-1/2 H D^-1/2,   D = diag(H),
//     whose eigenvalues lie in [0, p] and equal 1 +- rho for two variables with correlation rho. A
//     small eigenvalue is a direction along which the cost is flat compared with how well each
//     variable is determined alone: a valley (the paper's E-beta hyperbola of a bouncing ball is
//     the eigenvector ~ (log E, log beta) with loadings of equal sign: E beta^a = const).
//
// Verdict per variable: identifiable unless one of these flags names it:
//   kNoSensitivity          H_ii <= 0: the cost does not curve upwards along it.
//   kLargeUncertainty       marginal relative standard uncertainty > max_relative_uncertainty
//                           (variables with a relative scale: positive quantities, vectors).
//   kCorrelatedPair         |correlation| > max_correlation with another variable.
//   kDegenerateCombination  it loads >= min_loading on an eigenvector of H~ with eigenvalue <
//                           min_scaled_eigenvalue, or >= kUnboundedLoading on a singular one
//                           (its uncertainty is then infinite).
// A variable can be "identifiable" with a tiny formal uncertainty on noise-free synthetic data and
// still sit in a valley with another: the flags are reported separately so callers can tell a
// well-determined value from a well-determined combination.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/inverse/fit.h"
#include "core/inverse/job_config.h"
#include "core/inverse/objective_pool.h"
#include "core/inverse/parameter_space.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::inverse {

// How step 1 measures the curvature H.
enum class CurvatureMethod {
  // Central differences of the adjoint gradient (above): 1 + 2p forward+adjoint runs. Sees the
  // cost's own curvature, negative directions included (a saddle, a maximum).
  kGradientDifferences,
  // Gauss-Newton, H ~ J^T J from central differences of the per-point residuals (cost =
  // |r|^2 / 2): 1 + 2p forward runs, no adjoint, about half the cost of the above. Always positive
  // semi-definite; at a fit whose residuals are at the noise it agrees with the above to first
  // order (the second-order term averages out). The per-result uncertainty uses it. Central, not
  // forward, differences: the O(s) error of a forward difference is small next to a column of J
  // but not next to the small cross terms of two weakly correlated variables (it flipped the sign
  // of a correlation of 0.13 between E and a launch velocity).
  kGaussNewton,
};

struct IdentifiabilityOptions {
  CurvatureMethod curvature = CurvatureMethod::kGradientDifferences;
  // s, the central-difference step in the optimiser's variables [-] (log variables: a 1 % change;
  // gravity: 0.01 m/s^2), > 0. Large enough that the piecewise-smooth cost (points switch cells)
  // averages out, small next to the curvature scale of the valleys we look for.
  double step = 1e-2;
  // Worker threads for the evaluations; 0 = std::thread::hardware_concurrency(), >= 0.
  int threads = 0;
  // N_eff, the number of independent residuals [-]; 0 = the number of observed points in the
  // fitted frames. >= 0.
  double num_effective_samples = 0.0;
  // Lower bound of the residual standard deviation sigma [m], >= 0: a noise-free synthetic fit can
  // reach C_min ~ 0, which would make every uncertainty vanish; a sensor's depth resolution is a
  // sensible floor. 0 = no floor.
  double min_residual_sigma = 0.0;
  // Flag thresholds (see the top of the file). 0.1: a value known only to +-10 % (1 sigma) is not
  // a measurement. 0.95: the paper's E-beta valley and textbook collinearity limits. 0.05 is the
  // eigenvalue 1 - 0.95 of a pair correlated at 0.95, so the two pair criteria agree. 0.3: a
  // loading of 0.3 carries 9 % of the direction, below that a variable is a bystander.
  double max_relative_uncertainty = 0.1;  // (0, inf)
  double max_correlation = 0.95;          // (0, 1)
  double min_scaled_eigenvalue = 0.05;    // (0, 1)
  double min_loading = 0.3;               // (0, 1)

  // InvalidArgument naming the field and value, e.g.
  // "IdentifiabilityOptions.step = 0: must be positive and finite".
  Status Validate() const;
};

enum class IdentifiabilityFlag {
  kNoSensitivity,
  kLargeUncertainty,
  kCorrelatedPair,
  kDegenerateCombination,
};
// "no_sensitivity" | "large_uncertainty" | "correlated_pair" | "degenerate_combination".
const char* ToString(IdentifiabilityFlag flag);

// One optimiser variable at the optimum.
struct VariableIdentifiability {
  std::string name;       // ParameterSpace variable name: "youngs_modulus", "gravity[2]", ...
  std::string parameter;  // the fitted parameter it belongs to: "youngs_modulus", "gravity", ...
  std::string unit;       // of value and standard_uncertainty
  double variable = 0.0;  // x* [-]
  double value = 0.0;     // physical value (ground tilt: the variable itself, radians)
  // Marginal standard uncertainty of the variable and of the physical value; +inf when the
  // Hessian is singular along a direction the variable loads on by >= kUnboundedLoading (see
  // CovarianceFromHessian).
  double variable_uncertainty = 0.0;
  double standard_uncertainty = 0.0;
  // standard_uncertainty / scale (positive quantities: their value; vector entries: the vector's
  // norm); negative when the variable has no natural scale (ground plane, linear stiffness field).
  double relative_uncertainty = -1.0;
  // With the Gauss-Newton curvature (step 2b): standard_uncertainty / independent_uncertainty,
  // >= 1, where independent_uncertainty is the Laplace figure that treats every observed point as
  // an independent sample; > 1 when the residuals are correlated within and across frames
  // (correlated_residuals.h). 1 otherwise.
  double correlated_residual_factor = 1.0;
  double independent_uncertainty = 0.0;
  std::vector<IdentifiabilityFlag> flags;
  bool identifiable() const { return flags.empty(); }
};

// A direction in variable space along which the cost is flat for its scale
// (kDegenerateCombination).
struct DegenerateCombination {
  double scaled_eigenvalue = 0.0;  // of H~ [-]
  // Unit eigenvector of H~ mapped back to the variables (v_i / sqrt(H_ii), renormalised): moving
  // x by t * direction keeps the cost nearly constant. For log variables, direction (a, b) means
  // p_1^(1/a) ~ p_2^(-1/b) along the valley.
  std::vector<std::pair<std::string, double>> loadings;  // variables with |loading| >= min_loading
  Eigen::VectorXd direction;                             // all variables
};

// Step 3 of the method on a given symmetric Hessian H [m^2] in the optimiser's variables, with
// Cov = variance_scale * H^-1 (variance_scale = sigma^2 / N_eff): the eigen-decomposition of the
// unit-diagonal H~ over the variables with H_ii > 0 ("kept"), and the covariance by the
// pseudo-inverse of H~ (eigenvalues <= 1e-10 of the largest count as singular). A variable loading
// >= kUnboundedLoading on a singular direction is unbounded: +inf variance, NaN correlation with
// bounded variables, and with other unbounded ones the limit as the singular eigenvalues go to
// zero (+-1 within one valley); the others keep finite values from the determined directions.
// Variables not kept: +inf, NaN.
inline constexpr double kUnboundedLoading = 0.1;
struct HessianCovariance {
  std::vector<int> kept;                // variables with H_ii > 0, ascending
  Eigen::VectorXd scaled_eigenvalues;   // of H~ over the kept variables, ascending
  Eigen::MatrixXd scaled_eigenvectors;  // columns, same order; rows follow `kept`
  std::vector<bool> singular;           // per eigenvalue
  std::vector<bool> unbounded;          // per variable (all p)
  Eigen::MatrixXd covariance;           // p x p [-]
  Eigen::MatrixXd correlation;          // p x p [-]
};
HessianCovariance CovarianceFromHessian(const Eigen::MatrixXd& h, double variance_scale);

struct IdentifiabilityReport {
  std::vector<VariableIdentifiability> variables;
  // C_min [m^2] at the analysed parameters (with a frame loss other than least squares, the
  // reweighted least-squares cost, TrajectoryObjective::reweighted_cost, which scales the noise)
  double cost = 0.0;
  Eigen::VectorXd gradient;            // dC/dx at x* [m^2] (should be ~0 at an optimum)
  double num_effective_samples = 0.0;  // N_eff used [-]
  double residual_sigma = 0.0;         // sigma [m]
  // Step 2b (Gauss-Newton only): the frames the correlated-residual covariance clustered by and
  // its Bartlett window (AutomaticBandwidth) [frames]; 0 when it did not run.
  int correlated_residual_frames = 0;
  int correlated_residual_bandwidth = 0;
  CurvatureMethod curvature = CurvatureMethod::kGradientDifferences;  // how H was measured
  Eigen::MatrixXd hessian;                                            // H [m^2], symmetrised
  double hessian_asymmetry = 0.0;  // |H - H^T| / |H| before symmetrising (FD noise) [-]
  bool hessian_positive_definite = false;
  Eigen::MatrixXd covariance;           // Cov(x) [-]; +inf rows and columns of unbounded variables
  Eigen::MatrixXd correlation;          // [-]; NaN (JSON null) between unbounded and bounded
  Eigen::VectorXd scaled_eigenvalues;   // of H~, ascending [-]
  Eigen::MatrixXd scaled_eigenvectors;  // columns, same order
  std::vector<std::pair<std::string, std::string>> correlated_pairs;
  std::vector<DegenerateCombination> degenerate_combinations;
  int evaluations = 0;
  double seconds = 0.0;

  // The entry of variable `name`, or null.
  const VariableIdentifiability* Find(const std::string& name) const;
};

// The analysis at `parameters` (base values with the fitted ones at the optimum) for the variables
// of `space`. InvalidArgument for invalid options; FailedPrecondition when the simulation diverges
// at the optimum or at a step of the difference stencil (a smaller step may help); errors of the
// factory or the adjoint are passed on.
Result<IdentifiabilityReport> AnalyzeIdentifiability(const ObjectiveFactory& make_objective,
                                                     const ParameterSpace& space,
                                                     const fem::PhysicalParameters& parameters,
                                                     const IdentifiabilityOptions& options = {});

// The same for a finished fit of `capture` under `config`, at its best start.
Result<IdentifiabilityReport> AnalyzeIdentifiability(const capture::Capture& capture,
                                                     const JobConfig& config, const FitResult& fit,
                                                     const IdentifiabilityOptions& options = {});

// result.json's "identifiability" object:
//   {"method": "...", "cost": C, "residual_sigma": s, "num_effective_samples": N,
//    "hessian_positive_definite": b, "hessian_asymmetry": a,
//    "variables": [{"name", "parameter", "unit", "value", "standard_uncertainty",
//                   "relative_uncertainty" (null without a scale), "identifiable", "flags": []}],
//    "correlation": [[..]], "hessian": [[..]], "gradient": [..],
//    "scaled_eigenvalues": [..], "correlated_pairs": [["a", "b"]],
//    "degenerate_combinations": [{"scaled_eigenvalue", "loadings": {"name": w}}],
//    "evaluations": n, "seconds": t}
// Infinite uncertainties are written as null.
nlohmann::json ToJson(const IdentifiabilityReport& report);

}  // namespace softid::inverse
