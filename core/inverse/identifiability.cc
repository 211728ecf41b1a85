#include "core/inverse/identifiability.h"

#include <spdlog/spdlog.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <mutex>
#include <thread>

#include "core/capture/capture.h"
#include "core/common/check.h"
#include "core/common/json_fields.h"
#include "core/inverse/correlated_residuals.h"
#include "core/inverse/objective_pool.h"
#include "core/inverse/objective_settings.h"
#include "core/inverse/observed_frames.h"

namespace softid::inverse {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
// Scaled eigenvalues below this fraction of the largest count as exactly singular (no finite
// uncertainty along them); round-off of a finite-difference Hessian is far above 1e-12.
constexpr double kSingularEigenvalue = 1e-10;

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Says how many of the curvature's simulations are done, every kSecondsBetweenLines at most and
// only once that long has passed: the analysis of a quick fit is silent, that of a slow one (fine
// grid, many substeps: minutes) is not.
class CurvatureProgress {
 public:
  explicit CurvatureProgress(int total) : total_(total) {}
  void OneDone() {
    const int done = ++done_;
    std::lock_guard lock(mutex_);
    const double now = SecondsSince(begin_);
    if (now - last_line_ < kSecondsBetweenLines) return;
    last_line_ = now;
    spdlog::info(
        "uncertainty: {}/{} simulations at and around the optimum, {:.0f} s, ~{:.0f} s left", done,
        total_, now, now * (total_ - done) / std::max(1, done));
  }

 private:
  static constexpr double kSecondsBetweenLines = 20.0;
  const int total_;
  const std::chrono::steady_clock::time_point begin_ = std::chrono::steady_clock::now();
  std::atomic<int> done_{0};
  std::mutex mutex_;
  double last_line_ = 0.0;
};

// The fitted parameter a variable belongs to: "gravity[2]" -> "gravity".
std::string ParameterOf(const std::string& variable) {
  const size_t end = variable.find_first_of("[.");
  return end == std::string::npos ? variable : variable.substr(0, end);
}

// Physical value of variable i at x, with its unit and the scale its relative uncertainty refers
// to (<= 0: none).
struct PhysicalValue {
  double value = 0.0;
  double scale = 0.0;
  std::string unit;
};

PhysicalValue ValueOf(const ParameterSpace& space, const fem::PhysicalParameters& base,
                      const std::vector<double>& x, int i) {
  const std::string& name = space.variable_names()[i];
  const std::string parameter = ParameterOf(name);
  fem::PhysicalParameters p = space.ToParameters(x.data(), base);
  PhysicalValue out;
  const fem::ParameterInfo* info = fem::FindParameter(parameter);
  if (info == nullptr) return out;
  out.unit = info->unit;
  if (info->shape == fem::ParameterShape::kScalar) {
    out.value = p.*info->scalar;
    out.scale = std::abs(out.value);
    return out;
  }
  if (info->shape == fem::ParameterShape::kVector3) {
    const Eigen::Vector3d& vector = p.*info->vector;
    out.value = vector[name[name.find('[') + 1] - '0'];
    out.scale = vector.norm();
    return out;
  }
  if (info->shape == fem::ParameterShape::kPlane) {
    if (name == parameter + ".offset") {
      out.value = p.ground ? p.ground->offset : 0.0;
      out.unit = "m";
    } else {  // tilt: radians for small tilts around the start normal
      out.value = x[i];
      out.unit = "rad";
    }
    return out;
  }
  if (info->shape == fem::ParameterShape::kPose) {
    const bool rotation = name.find(".rotation[") != std::string::npos;
    const Eigen::Vector3d& vector = rotation ? p.initial_pose.rotation : p.initial_pose.translation;
    out.value = vector[name[name.find('[') + 1] - '0'];
    out.scale = vector.norm();
    out.unit = rotation ? "rad" : "m";
    return out;
  }
  if (info->shape == fem::ParameterShape::kStiffnessField) {
    // Index after "stiffness_field[" may have several digits.
    const int k = std::stoi(name.substr(name.find('[') + 1));
    if (p.stiffness_field.kind == fem::StiffnessField::Kind::kRegions) {
      out.value = p.stiffness_field.regions[k].scale;
      out.scale = std::abs(out.value);
      out.unit = "1";
    } else {
      out.value = p.stiffness_field.log_gradient[k];
      out.unit = "1/m";
    }
  }
  return out;
}

struct Evaluation {
  double cost = 0.0;
  Eigen::VectorXd gradient;  // in the variables
};

}  // namespace

Status IdentifiabilityOptions::Validate() const {
  const auto positive = [](double v) { return v > 0.0 && std::isfinite(v); };
  if (!positive(step))
    return json::Invalid("IdentifiabilityOptions.step", step, "must be positive and finite");
  if (threads < 0) return json::Invalid("IdentifiabilityOptions.threads", threads, "must be >= 0");
  if (!(num_effective_samples >= 0.0) || !std::isfinite(num_effective_samples)) {
    return json::Invalid("IdentifiabilityOptions.num_effective_samples", num_effective_samples,
                         "must be finite and >= 0 (0 = the number of observed points)");
  }
  if (!(min_residual_sigma >= 0.0) || !std::isfinite(min_residual_sigma)) {
    return json::Invalid("IdentifiabilityOptions.min_residual_sigma", min_residual_sigma,
                         "must be finite and >= 0");
  }
  if (!positive(max_relative_uncertainty)) {
    return json::Invalid("IdentifiabilityOptions.max_relative_uncertainty",
                         max_relative_uncertainty, "must be positive and finite");
  }
  const auto in_unit = [](double v) { return v > 0.0 && v < 1.0; };
  if (!in_unit(max_correlation))
    return json::Invalid("IdentifiabilityOptions.max_correlation", max_correlation,
                         "must lie in (0, 1)");
  if (!in_unit(min_scaled_eigenvalue))
    return json::Invalid("IdentifiabilityOptions.min_scaled_eigenvalue", min_scaled_eigenvalue,
                         "must lie in (0, 1)");
  if (!in_unit(min_loading))
    return json::Invalid("IdentifiabilityOptions.min_loading", min_loading, "must lie in (0, 1)");
  return Status::Ok();
}

const char* ToString(IdentifiabilityFlag flag) {
  switch (flag) {
    case IdentifiabilityFlag::kNoSensitivity: return "no_sensitivity";
    case IdentifiabilityFlag::kLargeUncertainty: return "large_uncertainty";
    case IdentifiabilityFlag::kCorrelatedPair: return "correlated_pair";
    case IdentifiabilityFlag::kDegenerateCombination: return "degenerate_combination";
  }
  return "?";
}

const VariableIdentifiability* IdentifiabilityReport::Find(const std::string& name) const {
  for (const VariableIdentifiability& v : variables) {
    if (v.name == name) return &v;
  }
  return nullptr;
}

namespace {

// H~ = D^-1/2 H D^-1/2 over the variables with upward curvature (D = diag H), and its
// eigen-decomposition into `out`; returns D^-1/2 over the kept variables.
Eigen::VectorXd DecomposeScaledHessian(const Eigen::MatrixXd& h, HessianCovariance* out) {
  const int p = static_cast<int>(h.rows());
  // Variables without upward curvature are left out of the scaled analysis.
  for (int i = 0; i < p; ++i) {
    if (h(i, i) > 0.0 && std::isfinite(h(i, i))) out->kept.push_back(i);
  }
  const int k = static_cast<int>(out->kept.size());
  Eigen::VectorXd d_inv_sqrt(k);
  Eigen::MatrixXd scaled(k, k);
  for (int a = 0; a < k; ++a) d_inv_sqrt[a] = 1.0 / std::sqrt(h(out->kept[a], out->kept[a]));
  for (int a = 0; a < k; ++a)
    for (int b = 0; b < k; ++b)
      scaled(a, b) = h(out->kept[a], out->kept[b]) * d_inv_sqrt[a] * d_inv_sqrt[b];
  if (k > 0) {
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(scaled);
    out->scaled_eigenvalues = eigen.eigenvalues();
    out->scaled_eigenvectors = eigen.eigenvectors();
  }
  return d_inv_sqrt;
}

// The directions of H~ the cost does not curve along (eigenvalue at or below `lambda_floor`) are
// marked singular in `out`; returns 1 / lambda per eigenvalue (0 where singular) and sets, per
// kept variable, whether it loads on a singular direction (is unbounded).
Eigen::VectorXd PseudoInverseEigenvalues(double lambda_floor, HessianCovariance* out,
                                         std::vector<bool>* unbounded_kept) {
  const Eigen::VectorXd& lambda = out->scaled_eigenvalues;
  const Eigen::MatrixXd& vectors = out->scaled_eigenvectors;
  const int k = static_cast<int>(out->kept.size());
  out->singular.assign(k, false);
  unbounded_kept->assign(k, false);
  Eigen::VectorXd inverse_lambda = Eigen::VectorXd::Zero(k);
  for (int e = 0; e < k; ++e) {
    if (lambda[e] > lambda_floor) {
      inverse_lambda[e] = 1.0 / lambda[e];
      continue;
    }
    out->singular[e] = true;
    for (int a = 0; a < k; ++a) {
      if (std::abs(vectors(a, e)) >= kUnboundedLoading) (*unbounded_kept)[a] = true;
    }
  }
  return inverse_lambda;
}

}  // namespace

HessianCovariance CovarianceFromHessian(const Eigen::MatrixXd& h, double variance_scale) {
  SOFTID_DEMAND(h.rows() == h.cols());
  const int p = static_cast<int>(h.rows());
  HessianCovariance out;
  const Eigen::VectorXd d_inv_sqrt = DecomposeScaledHessian(h, &out);
  const int k = static_cast<int>(out.kept.size());
  const Eigen::VectorXd& lambda = out.scaled_eigenvalues;
  const Eigen::MatrixXd& vectors = out.scaled_eigenvectors;

  // Cov over the kept variables = variance_scale D^-1/2 V Lambda^+ V^T D^-1/2 (pseudo-inverse:
  // singular directions left out), and infinite variances for the variables that load on a
  // singular direction. A direction the cost does not curve along (or, through finite-difference
  // noise, curves slightly down along) leaves every variable in it undetermined; a variable that
  // only grazes it (|loading| < kUnboundedLoading: moving along the valley by t moves it by under
  // t / 10 in scaled units) keeps the uncertainty of the determined directions. Clamping the
  // eigenvalue instead made every marginal variance infinite and every correlation +-1.
  const double lambda_max = k > 0 ? std::max(lambda.maxCoeff(), 0.0) : 0.0;
  const double lambda_floor = kSingularEigenvalue * std::max(lambda_max, 1.0);
  std::vector<bool> unbounded_kept;
  const Eigen::VectorXd inverse_lambda =
      PseudoInverseEigenvalues(lambda_floor, &out, &unbounded_kept);
  const Eigen::MatrixXd scaled_covariance =
      vectors * inverse_lambda.asDiagonal() * vectors.transpose();
  // Between two unbounded variables the correlation is its limit as the singular eigenvalues go
  // to zero (+-1 for a pair in one valley): from the eigenvalues clamped to the floor.
  Eigen::VectorXd clamped_inverse_lambda(k);
  for (int e = 0; e < k; ++e) clamped_inverse_lambda[e] = 1.0 / std::max(lambda[e], lambda_floor);
  const Eigen::MatrixXd limit_covariance =
      vectors * clamped_inverse_lambda.asDiagonal() * vectors.transpose();

  out.unbounded.assign(p, false);
  for (int a = 0; a < k; ++a) out.unbounded[out.kept[a]] = unbounded_kept[a];
  out.covariance = Eigen::MatrixXd::Constant(p, p, kInfinity);
  out.correlation = Eigen::MatrixXd::Constant(p, p, std::nan(""));
  for (int i = 0; i < p; ++i) out.correlation(i, i) = 1.0;
  const auto correlation = [](const Eigen::MatrixXd& c, int a, int b) {
    return c(a, b) / std::sqrt(c(a, a) * c(b, b));
  };
  for (int a = 0; a < k; ++a) {
    for (int b = 0; b < k; ++b) {
      const int i = out.kept[a], j = out.kept[b];
      if (!unbounded_kept[a] && !unbounded_kept[b]) {
        out.covariance(i, j) =
            variance_scale * scaled_covariance(a, b) * d_inv_sqrt[a] * d_inv_sqrt[b];
        if (i != j) out.correlation(i, j) = correlation(scaled_covariance, a, b);
      } else if (unbounded_kept[a] && unbounded_kept[b] && i != j) {
        out.correlation(i, j) = correlation(limit_covariance, a, b);
      }
    }
  }
  return out;
}

namespace {

// The cost's curvature at the optimum in the optimiser's variables, and what came with it.
struct Curvature {
  double cost = 0.0;         // C(x*) [m^2]; with a frame loss, its reweighted least-squares cost
  Eigen::VectorXd gradient;  // dC/dx at x* [m^2]
  Eigen::MatrixXd hessian;   // symmetric [m^2]
  double asymmetry = 0.0;    // |H - H^T| / |H| before symmetrising [-]
  int num_points = 0;        // observed points in the fitted frames
  int evaluations = 0;
  // Gauss-Newton only: each fitted frame's share J_k^T r_k of the gradient, in time order.
  std::vector<Eigen::VectorXd> frame_gradients;
};

// The difference stencil around the optimum: the optimiser's variables there (x0) and the step.
struct Stencil {
  Stencil(const ParameterSpace& space, const fem::PhysicalParameters& parameters,
          const IdentifiabilityOptions& options)
      : space(space),
        parameters(parameters),
        p(space.NumVariables()),
        x0(space.ToVariables(parameters)),
        s(options.step) {}

  // The parameters at x = x0 + offset e_variable (x0 itself when variable < 0), with x, or why
  // the stencil cannot use them.
  Result<fem::PhysicalParameters> Point(int variable, double offset, std::vector<double>* x) const {
    *x = x0;
    if (variable >= 0) (*x)[variable] += offset;
    fem::PhysicalParameters at = space.ToParameters(x->data(), parameters);
    if (Status valid = at.Validate(); !valid.ok()) {
      return Status::FailedPrecondition(
          "identifiability: invalid parameters at a difference step (lower "
          "IdentifiabilityOptions.step): " +
          valid.message());
    }
    return at;
  }

  // The simulation diverged at the point `sign` s along `variable` (at x0 when variable < 0).
  Status Diverged(int variable, const char* sign) const {
    return Status::FailedPrecondition(
        variable < 0
            ? std::string("identifiability: the simulation diverges at the optimum")
            : "identifiability: the simulation diverges at " + space.variable_names()[variable] +
                  sign + std::to_string(s) + " (lower IdentifiabilityOptions.step)");
  }

  const ParameterSpace& space;
  const fem::PhysicalParameters& parameters;
  const int p;  // variables
  const std::vector<double> x0;
  const double s;
};

int PointsInFittedFrames(const TrajectoryObjective& objective) {
  int n = 0;
  for (const ObservedFrame& frame : objective.frames()) {
    if (!frame.heldout) n += static_cast<int>(frame.points.size());
  }
  return n;
}

// How many residuals each frame contributes to TrajectoryObjective::EvaluateResiduals, in its
// order (the fitted frames with points, among the active ones).
std::vector<int> ResidualsPerFrame(const TrajectoryObjective& objective) {
  std::vector<int> sizes;
  for (int k = 0; k < objective.active_frames(); ++k) {
    const ObservedFrame& frame = objective.frames()[k];
    if (!frame.heldout && !frame.points.empty()) sizes.push_back(int(frame.points.size()));
  }
  return sizes;
}

int Threads(const IdentifiabilityOptions& options) {
  return options.threads > 0 ? options.threads
                             : static_cast<int>(std::thread::hardware_concurrency());
}

// H e_j ~ (g(x* + s e_j) - g(x* - s e_j)) / (2 s): 1 + 2p forward+adjoint runs.
Result<Curvature> CurvatureByGradientDifferences(const ObjectiveFactory& make_objective,
                                                 const Stencil& stencil,
                                                 const IdentifiabilityOptions& options) {
  const int p = stencil.p;
  const double s = stencil.s;
  // Task 0: the centre; task 1 + 2 j (+ 1): x0 -+ s e_j.
  const int num_tasks = 1 + 2 * p;
  std::vector<Evaluation> results(num_tasks);
  Curvature out;
  CurvatureProgress progress(num_tasks);
  SOFTID_RETURN_IF_ERROR(RunOnObjectives(
      make_objective, num_tasks, Threads(options), [&](TrajectoryObjective& objective, int task) {
        const int variable = task > 0 ? (task - 1) / 2 : -1;
        std::vector<double> x;
        SOFTID_ASSIGN_OR_RETURN(const fem::PhysicalParameters at,
                                stencil.Point(variable, task % 2 == 1 ? -s : s, &x));
        SOFTID_ASSIGN_OR_RETURN(ObjectiveEvaluation evaluation,
                                objective.Evaluate(at, /*with_gradient=*/true));
        if (evaluation.diverged) return stencil.Diverged(variable, task % 2 == 1 ? " - " : " + ");
        Evaluation& result = results[task];
        result.cost = evaluation.reweighted_cost;
        result.gradient.resize(p);
        stencil.space.ChainGradient(evaluation.gradient, x.data(), result.gradient.data());
        if (task == 0) out.num_points = PointsInFittedFrames(objective);
        progress.OneDone();
        return Status::Ok();
      }));
  out.evaluations = num_tasks;
  out.cost = results[0].cost;
  out.gradient = results[0].gradient;
  Eigen::MatrixXd h(p, p);
  for (int j = 0; j < p; ++j)
    h.col(j) = (results[2 + 2 * j].gradient - results[1 + 2 * j].gradient) / (2.0 * s);
  const double norm = h.norm();
  out.asymmetry = norm > 0.0 ? (h - h.transpose()).norm() / norm : 0.0;
  out.hessian = 0.5 * (h + h.transpose());
  return out;
}

// H ~ J^T J with J e_j ~ (r(x* + s e_j) - r(x* - s e_j)) / (2 s) for the residuals r of
// TrajectoryObjective::EvaluateResiduals (C = |r|^2 / 2): 1 + 2p forward runs, no adjoint. Exact
// to first order at a fit whose residuals are at the noise (the second-order term averages out).
Result<Curvature> CurvatureByGaussNewton(const ObjectiveFactory& make_objective,
                                         const Stencil& stencil,
                                         const IdentifiabilityOptions& options) {
  const int p = stencil.p;
  const double s = stencil.s;
  const int num_tasks = 1 + 2 * p;  // the centre, then x0 -+ s e_j
  std::vector<Eigen::VectorXd> residuals(num_tasks);
  std::vector<int> frame_sizes;
  Curvature out;
  CurvatureProgress progress(num_tasks);
  SOFTID_RETURN_IF_ERROR(RunOnObjectives(
      make_objective, num_tasks, Threads(options), [&](TrajectoryObjective& objective, int task) {
        const int variable = task > 0 ? (task - 1) / 2 : -1;
        const double offset = task % 2 == 1 ? -s : s;
        std::vector<double> x;
        SOFTID_ASSIGN_OR_RETURN(const fem::PhysicalParameters at,
                                stencil.Point(variable, offset, &x));
        SOFTID_ASSIGN_OR_RETURN(ObjectiveEvaluation evaluation,
                                objective.EvaluateResiduals(at, &residuals[task]));
        if (evaluation.diverged) return stencil.Diverged(variable, offset < 0 ? " - " : " + ");
        if (task == 0) {
          out.cost = evaluation.reweighted_cost;
          out.num_points = PointsInFittedFrames(objective);
          frame_sizes = ResidualsPerFrame(objective);
        }
        progress.OneDone();
        return Status::Ok();
      }));
  Eigen::MatrixXd jacobian(residuals[0].size(), p);
  for (int j = 0; j < p; ++j)
    jacobian.col(j) = (residuals[2 + 2 * j] - residuals[1 + 2 * j]) / (2.0 * s);
  out.evaluations = num_tasks;
  out.hessian = jacobian.transpose() * jacobian;
  out.gradient = jacobian.transpose() * residuals[0];
  out.frame_gradients = FrameGradients(jacobian, residuals[0], frame_sizes);
  return out;
}

// Noise scale: sigma^2 = 2 C_min N / (N - p), floored (see the header), into the report. Returns
// the factor of H^-1 in the covariance.
double SetNoiseScale(const IdentifiabilityOptions& options, int num_points, int p,
                     IdentifiabilityReport* report) {
  const double n_eff =
      options.num_effective_samples > 0.0 ? options.num_effective_samples : double(num_points);
  report->num_effective_samples = n_eff;
  const double dof = n_eff > p ? n_eff - p : std::max(n_eff, 1.0);
  const double sigma2 = std::max(2.0 * std::max(report->cost, 0.0) * std::max(n_eff, 1.0) / dof,
                                 options.min_residual_sigma * options.min_residual_sigma);
  report->residual_sigma = std::sqrt(sigma2);
  return sigma2 / std::max(n_eff, 1.0);  // Cov = variance_scale * H^-1
}

// Step 2b: each variable's variance widened to the frame-correlated estimate where that is larger,
// Cov <- D Cov D (the Laplace correlations stay). Variables without a finite variance keep it.
void WidenForCorrelatedResiduals(const Curvature& curvature, double variance_scale,
                                 IdentifiabilityReport* report) {
  Eigen::MatrixXd& covariance = report->covariance;
  const int p = static_cast<int>(covariance.rows());
  if (!(variance_scale > 0.0) || curvature.frame_gradients.size() < 2) return;
  std::vector<int> finite;
  for (int i = 0; i < p; ++i)
    if (std::isfinite(covariance(i, i)) && covariance(i, i) > 0.0) finite.push_back(i);
  Eigen::MatrixXd h_pinv = Eigen::MatrixXd::Zero(p, p);  // Cov / variance_scale = H^+
  for (int i : finite)
    for (int j : finite) h_pinv(i, j) = covariance(i, j) / variance_scale;
  const int frames = static_cast<int>(curvature.frame_gradients.size());
  int bandwidth = 0;
  const Eigen::MatrixXd sandwich =
      CorrelatedResidualCovariance(h_pinv, curvature.frame_gradients, &bandwidth);
  report->correlated_residual_frames = frames;
  report->correlated_residual_bandwidth = bandwidth;
  Eigen::VectorXd factor = Eigen::VectorXd::Ones(p);
  for (int i : finite) factor[i] = std::max(1.0, std::sqrt(sandwich(i, i) / covariance(i, i)));
  for (int i : finite)
    for (int j : finite) covariance(i, j) *= factor[i] * factor[j];
  for (int i = 0; i < p; ++i) report->variables[i].correlated_residual_factor = factor[i];
}

// Per-variable uncertainties in physical units (d value / d x by central differences of the
// transform: exact enough, and the same code for every parameterisation).
void SetUncertainties(const Stencil& stencil, const IdentifiabilityOptions& options,
                      IdentifiabilityReport* report) {
  const std::vector<double>& x0 = stencil.x0;
  for (int i = 0; i < stencil.p; ++i) {
    VariableIdentifiability& v = report->variables[i];
    const PhysicalValue value = ValueOf(stencil.space, stencil.parameters, x0, i);
    v.value = value.value;
    v.unit = value.unit;
    std::vector<double> x = x0;
    const double dx = 1e-6;
    x[i] = x0[i] + dx;
    const double plus = ValueOf(stencil.space, stencil.parameters, x, i).value;
    x[i] = x0[i] - dx;
    const double minus = ValueOf(stencil.space, stencil.parameters, x, i).value;
    const double slope = std::abs(plus - minus) / (2.0 * dx);
    v.variable_uncertainty = std::sqrt(report->covariance(i, i));
    v.standard_uncertainty =
        std::isfinite(v.variable_uncertainty) ? slope * v.variable_uncertainty : kInfinity;
    v.independent_uncertainty = v.standard_uncertainty / v.correlated_residual_factor;
    v.relative_uncertainty = value.scale > 0.0 ? v.standard_uncertainty / value.scale : -1.0;
    if (v.relative_uncertainty > options.max_relative_uncertainty &&
        v.flags.empty()) {  // (no sensitivity already says more)
      v.flags.push_back(IdentifiabilityFlag::kLargeUncertainty);
    }
  }
}

void AddFlag(VariableIdentifiability& v, IdentifiabilityFlag flag) {
  if (std::find(v.flags.begin(), v.flags.end(), flag) == v.flags.end()) v.flags.push_back(flag);
}

// Pairs of kept variables correlated beyond options.max_correlation.
void FlagCorrelatedPairs(const std::vector<int>& kept, const IdentifiabilityOptions& options,
                         IdentifiabilityReport* report) {
  const int k = static_cast<int>(kept.size());
  for (int a = 0; a < k; ++a) {
    for (int b = a + 1; b < k; ++b) {
      const int i = kept[a], j = kept[b];
      // (NaN, for a variable without a finite uncertainty, is not a correlation.)
      if (!(std::abs(report->correlation(i, j)) > options.max_correlation)) continue;
      report->correlated_pairs.emplace_back(report->variables[i].name, report->variables[j].name);
      for (int m : {i, j}) AddFlag(report->variables[m], IdentifiabilityFlag::kCorrelatedPair);
    }
  }
}

// Valleys: combinations of the kept variables whose scaled eigenvalue is below
// options.min_scaled_eigenvalue, which the data fix only together.
void AddDegenerateCombinations(const HessianCovariance& laplace, const Eigen::MatrixXd& h,
                               const IdentifiabilityOptions& options,
                               IdentifiabilityReport* report) {
  const std::vector<int>& kept = laplace.kept;
  const int k = static_cast<int>(kept.size());
  const int p = static_cast<int>(report->variables.size());
  const Eigen::VectorXd& lambda = laplace.scaled_eigenvalues;
  const Eigen::MatrixXd& vectors = laplace.scaled_eigenvectors;
  Eigen::VectorXd d_inv_sqrt(k);
  for (int a = 0; a < k; ++a) d_inv_sqrt[a] = 1.0 / std::sqrt(h(kept[a], kept[a]));
  for (int e = 0; e < k && k > 1; ++e) {
    if (!(lambda[e] < options.min_scaled_eigenvalue)) continue;
    DegenerateCombination combination;
    combination.scaled_eigenvalue = lambda[e];
    combination.direction = Eigen::VectorXd::Zero(p);
    for (int a = 0; a < k; ++a) combination.direction[kept[a]] = vectors(a, e) * d_inv_sqrt[a];
    combination.direction.normalize();
    // Flags and loadings from the scaled eigenvector (scale-free); the direction is for people.
    for (int a = 0; a < k; ++a) {
      const bool member = std::abs(vectors(a, e)) >= options.min_loading ||
                          (laplace.singular[e] && laplace.unbounded[kept[a]] &&
                           std::abs(vectors(a, e)) >= kUnboundedLoading);
      if (!member) continue;
      VariableIdentifiability& v = report->variables[kept[a]];
      combination.loadings.emplace_back(v.name, vectors(a, e));
      AddFlag(v, IdentifiabilityFlag::kDegenerateCombination);
    }
    report->degenerate_combinations.push_back(std::move(combination));
  }
}

}  // namespace

Result<IdentifiabilityReport> AnalyzeIdentifiability(const ObjectiveFactory& make_objective,
                                                     const ParameterSpace& space,
                                                     const fem::PhysicalParameters& parameters,
                                                     const IdentifiabilityOptions& options) {
  const auto begin = std::chrono::steady_clock::now();
  SOFTID_RETURN_IF_ERROR(options.Validate());
  const Stencil stencil(space, parameters, options);
  const int p = stencil.p;
  SOFTID_ASSIGN_OR_RETURN(const Curvature curvature,
                          options.curvature == CurvatureMethod::kGaussNewton
                              ? CurvatureByGaussNewton(make_objective, stencil, options)
                              : CurvatureByGradientDifferences(make_objective, stencil, options));

  IdentifiabilityReport report;
  report.evaluations = curvature.evaluations;
  report.curvature = options.curvature;
  report.cost = curvature.cost;
  report.gradient = curvature.gradient;
  report.hessian_asymmetry = curvature.asymmetry;
  const Eigen::MatrixXd& h = curvature.hessian;
  report.hessian = h;
  report.hessian_positive_definite =
      p > 0 && h.llt().info() == Eigen::Success && (h.diagonal().array() > 0.0).all();
  const double variance_scale = SetNoiseScale(options, curvature.num_points, p, &report);

  report.variables.resize(p);
  for (int i = 0; i < p; ++i) {
    VariableIdentifiability& v = report.variables[i];
    v.name = space.variable_names()[i];
    v.parameter = ParameterOf(v.name);
    v.variable = stencil.x0[i];
  }
  const HessianCovariance laplace = CovarianceFromHessian(h, variance_scale);
  for (int i = 0; i < p; ++i) {
    if (std::find(laplace.kept.begin(), laplace.kept.end(), i) == laplace.kept.end())
      report.variables[i].flags.push_back(IdentifiabilityFlag::kNoSensitivity);
  }
  report.covariance = laplace.covariance;
  WidenForCorrelatedResiduals(curvature, variance_scale, &report);
  report.correlation = laplace.correlation;
  report.scaled_eigenvalues = laplace.scaled_eigenvalues;
  report.scaled_eigenvectors = laplace.scaled_eigenvectors;
  SetUncertainties(stencil, options, &report);
  FlagCorrelatedPairs(laplace.kept, options, &report);
  AddDegenerateCombinations(laplace, h, options, &report);
  report.seconds = SecondsSince(begin);
  return report;
}

Result<IdentifiabilityReport> AnalyzeIdentifiability(const capture::Capture& capture,
                                                     const JobConfig& config, const FitResult& fit,
                                                     const IdentifiabilityOptions& options) {
  SOFTID_RETURN_IF_ERROR(config.Validate());
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (fit.best < 0 || fit.best >= static_cast<int>(fit.starts.size()))
    return Status::FailedPrecondition("identifiability: the fit has no usable start");
  // The fit's grid, time step and frames (config may say "auto"; the fit resolved them, and it may
  // have left out the unpredictable frames).
  const JobConfig resolved_config = WithFitDiscretisation(config, fit);
  SOFTID_ASSIGN_OR_RETURN(geometry::TriangleMesh mesh, capture::LoadCaptureMesh(capture));
  SOFTID_ASSIGN_OR_RETURN(auto frames, LoadFittedFrames(capture, resolved_config));
  const double length = mesh.Bounds().sizes().maxCoeff();
  // The fit's own variables: the same reference (the base parameters) fixes the ground plane's
  // tangent basis.
  SOFTID_ASSIGN_OR_RETURN(ParameterSpace space,
                          ParameterSpace::Create(fit.fitted, fit.base, length));
  const fem::PhysicalParameters& optimum = fit.Best().final;
  const fem::SimulationOptions simulation = SimulationOptionsFor(resolved_config.solver);
  const cost::SurfaceCostOptions cost_options = CostOptionsFor(resolved_config.solver);
  const int substeps = resolved_config.solver.substeps;
  if (substeps < 1 ||
      (resolved_config.solver.cells == kAutoCells && resolved_config.solver.cell_size_m <= 0.0)) {
    return Status::InvalidArgument(
        "fit: the fit result does not say which grid and time step it used");
  }
  IdentifiabilityOptions resolved = options;
  if (resolved.threads == 0) resolved.threads = config.solver.threads;
  return AnalyzeIdentifiability(
      [&]() {
        auto objective =
            std::make_unique<TrajectoryObjective>(mesh, capture.fixed_region, optimum, simulation,
                                                  cost_options, frames, capture.fps, substeps);
        objective->SetFrameLoss(fit.frame_loss);
        return objective;
      },
      space, optimum, resolved);
}

namespace {

// A number, or null where it is not finite (JSON has no infinity or NaN).
nlohmann::json FiniteOrNull(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

nlohmann::json VectorJson(const Eigen::VectorXd& v) {
  nlohmann::json out = nlohmann::json::array();
  for (int i = 0; i < v.size(); ++i) out.push_back(FiniteOrNull(v[i]));
  return out;
}

nlohmann::json MatrixJson(const Eigen::MatrixXd& m) {
  nlohmann::json rows = nlohmann::json::array();
  for (int i = 0; i < m.rows(); ++i) {
    nlohmann::json row = nlohmann::json::array();
    for (int j = 0; j < m.cols(); ++j) row.push_back(FiniteOrNull(m(i, j)));
    rows.push_back(row);
  }
  return rows;
}

nlohmann::json VariableJson(const VariableIdentifiability& v) {
  nlohmann::json flags = nlohmann::json::array();
  for (IdentifiabilityFlag f : v.flags) flags.push_back(ToString(f));
  return {
      {"name", v.name},
      {"parameter", v.parameter},
      {"unit", v.unit},
      {"value", FiniteOrNull(v.value)},
      {"variable", FiniteOrNull(v.variable)},
      {"variable_uncertainty", FiniteOrNull(v.variable_uncertainty)},
      {"standard_uncertainty", FiniteOrNull(v.standard_uncertainty)},
      {"relative_uncertainty", v.relative_uncertainty >= 0.0 ? FiniteOrNull(v.relative_uncertainty)
                                                             : nlohmann::json(nullptr)},
      {"independent_uncertainty", FiniteOrNull(v.independent_uncertainty)},
      {"correlated_residual_factor", FiniteOrNull(v.correlated_residual_factor)},
      {"identifiable", v.identifiable()},
      {"flags", flags}};
}

nlohmann::json CombinationJson(const DegenerateCombination& c) {
  nlohmann::json loadings = nlohmann::json::object();
  for (const auto& [name, w] : c.loadings) loadings[name] = w;
  return {{"scaled_eigenvalue", FiniteOrNull(c.scaled_eigenvalue)},
          {"loadings", loadings},
          {"direction", VectorJson(c.direction)}};
}

}  // namespace

nlohmann::json ToJson(const IdentifiabilityReport& report) {
  nlohmann::json variables = nlohmann::json::array();
  for (const VariableIdentifiability& v : report.variables) variables.push_back(VariableJson(v));
  nlohmann::json pairs = nlohmann::json::array();
  for (const auto& [a, b] : report.correlated_pairs) pairs.push_back({a, b});
  nlohmann::json combinations = nlohmann::json::array();
  for (const DegenerateCombination& c : report.degenerate_combinations)
    combinations.push_back(CombinationJson(c));
  return {
      {"method", std::string("Laplace approximation: Cov(x) = 2 C_min / (N_eff - p) * H^-1, H ") +
                     (report.curvature == CurvatureMethod::kGaussNewton
                          ? "= J^T J (Gauss-Newton, forward differences of the residuals)"
                          : "by central differences of adjoint gradients") +
                     " in the optimiser's variables (log for positive quantities)" +
                     (report.correlated_residual_frames > 0
                          ? "; each variance widened to the frame-correlated (Newey-West) "
                            "sandwich estimate where that is larger"
                          : "")},
      {"correlated_residuals",
       {{"frames", report.correlated_residual_frames},
        {"bandwidth_frames", report.correlated_residual_bandwidth}}},
      {"cost", FiniteOrNull(report.cost)},
      {"residual_sigma", FiniteOrNull(report.residual_sigma)},
      {"num_effective_samples", FiniteOrNull(report.num_effective_samples)},
      {"hessian_positive_definite", report.hessian_positive_definite},
      {"hessian_asymmetry", FiniteOrNull(report.hessian_asymmetry)},
      {"variables", variables},
      {"gradient", VectorJson(report.gradient)},
      {"hessian", MatrixJson(report.hessian)},
      {"correlation", MatrixJson(report.correlation)},
      {"scaled_eigenvalues", VectorJson(report.scaled_eigenvalues)},
      {"correlated_pairs", pairs},
      {"degenerate_combinations", combinations},
      {"evaluations", report.evaluations},
      {"seconds", report.seconds},
  };
}

}  // namespace softid::inverse
