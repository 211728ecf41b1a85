#include "core/inverse/least_squares_refinement.h"

#include <ceres/ceres.h>

#include <cmath>
#include <cstdio>
#include <mutex>
#include <thread>

namespace softid::inverse {
namespace {

// Statistics of forward runs, merged from the Jacobian's worker threads.
struct RunStatistics {
  int evaluations = 0, failed_evaluations = 0;
  long long steps = 0, unconverged_steps = 0;
  double forward_seconds = 0.0;
};

// The residuals r(x) / sqrt(scale) as a Ceres cost function of one parameter block (the
// variables), with the Jacobian by central differences.
class ResidualFunction : public ceres::CostFunction {
 public:
  ResidualFunction(const std::vector<TrajectoryObjective*>& objectives, const ParameterSpace& space,
                   const fem::PhysicalParameters& base, double scale, double step,
                   RunStatistics* statistics)
      : objectives_(objectives),
        space_(space),
        base_(base),
        inverse_root_scale_(1.0 / std::sqrt(scale)),
        step_(step),
        statistics_(statistics),
        columns_plus_(objectives.size()),
        columns_minus_(objectives.size()) {
    set_num_residuals(objectives.front()->NumResiduals());
    mutable_parameter_block_sizes()->push_back(space.NumVariables());
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int n = space_.NumVariables();
    const int m = num_residuals();
    const double* x = parameters[0];
    Eigen::Map<Eigen::VectorXd> r(residuals, m);
    if (!ResidualsAt(*objectives_.front(), x, &residual_scratch_)) return false;
    r = residual_scratch_;
    if (jacobians == nullptr || jacobians[0] == nullptr) return true;

    // Column j on worker j mod W; a failed side falls back to a one-sided difference.
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> jacobian(
        jacobians[0], m, n);
    const int workers = std::min<int>(static_cast<int>(objectives_.size()), n);
    std::vector<char> ok(n, 1);
    auto work = [&](int w) {
      std::vector<double> shifted(x, x + n);
      Eigen::VectorXd& plus = columns_plus_[w];
      Eigen::VectorXd& minus = columns_minus_[w];
      for (int j = w; j < n; j += workers) {
        shifted[j] = x[j] + step_;
        const bool has_plus = ResidualsAt(*objectives_[w], shifted.data(), &plus);
        shifted[j] = x[j] - step_;
        const bool has_minus = ResidualsAt(*objectives_[w], shifted.data(), &minus);
        shifted[j] = x[j];
        if (has_plus && has_minus) {
          jacobian.col(j) = (plus - minus) / (2.0 * step_);
        } else if (has_plus) {
          jacobian.col(j) = (plus - r) / step_;
        } else if (has_minus) {
          jacobian.col(j) = (r - minus) / step_;
        } else {
          ok[j] = 0;
        }
      }
    };
    std::vector<std::thread> threads;
    for (int w = 1; w < workers; ++w) threads.emplace_back(work, w);
    work(0);
    for (std::thread& t : threads) t.join();
    return std::all_of(ok.begin(), ok.end(), [](char c) { return c != 0; });
  }

 private:
  // Scaled residuals at variables x; false when the parameters are invalid or the run diverges.
  bool ResidualsAt(TrajectoryObjective& objective, const double* x, Eigen::VectorXd* out) const {
    const fem::PhysicalParameters p = space_.ToParameters(x, base_);
    if (!p.Validate().ok()) {
      Count(nullptr);
      return false;
    }
    Result<ObjectiveEvaluation> evaluation =
        objective.EvaluateResiduals(p, out, TrajectoryObjective::ResidualWeighting::kLossValue);
    const bool ok = evaluation.ok() && !evaluation->diverged && out->allFinite();
    Count(evaluation.ok() ? &*evaluation : nullptr, ok);
    if (ok) *out *= inverse_root_scale_;
    return ok;
  }

  void Count(const ObjectiveEvaluation* evaluation, bool ok = false) const {
    std::lock_guard lock(mutex_);
    ++statistics_->evaluations;
    if (!ok) ++statistics_->failed_evaluations;
    if (evaluation == nullptr) return;
    statistics_->steps += evaluation->steps;
    statistics_->unconverged_steps += evaluation->unconverged_steps;
    statistics_->forward_seconds += evaluation->forward_seconds;
  }

  const std::vector<TrajectoryObjective*>& objectives_;
  const ParameterSpace& space_;
  const fem::PhysicalParameters& base_;
  double inverse_root_scale_;
  double step_;
  RunStatistics* statistics_;
  mutable std::mutex mutex_;
  mutable Eigen::VectorXd residual_scratch_;
  mutable std::vector<Eigen::VectorXd> columns_plus_, columns_minus_;
};

// Reports iterations, honours cancellation, and ends the solve where the forward runs' noise
// leaves nothing to measure. Ceres' function tolerance tests the actual change of the cost, but a
// forward run's cost is reproducible only to a few 1e-6 relative (Newton and GMRES stop at their
// tolerances), so near the minimum the actual changes are that noise (torus-drop: +-3e-6 relative
// with gain ratios of +-1e3) and Levenberg-Marquardt rejected step after step up to its limit.
// Converged instead when an accepted step's Gauss-Newton model predicted a relative decrease
// <= function_tolerance. (Ending at a rejected step shorter than the Jacobian's difference step
// would stop on noise sooner, but in a curved valley such a step can fail for the valley's
// curvature: not done.)
class IterationForwarder : public ceres::IterationCallback {
 public:
  IterationForwarder(const RefinementOptions& options, double scale)
      : options_(options), scale_(scale) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    if (summary.iteration > 0 && options_.on_iteration)
      options_.on_iteration(summary.iteration, summary.cost * scale_, summary.gradient_max_norm);
    if (options_.cancel != nullptr && options_.cancel->load()) return ceres::SOLVER_ABORT;
    if (summary.iteration == 0 || !summary.step_is_valid) return ceres::SOLVER_CONTINUE;
    char text[200];
    if (summary.step_is_successful && summary.relative_decrease > 0.0) {
      // relative_decrease = actual / predicted decrease; cost is the cost after the step.
      const double before = summary.cost + summary.cost_change;
      const double predicted = summary.cost_change / summary.relative_decrease / before;
      if (std::isfinite(predicted) && predicted <= options_.function_tolerance) {
        std::snprintf(text, sizeof text,
                      "Function tolerance reached by the model: predicted |cost change|/cost: "
                      "%.6e <= %.6e",
                      predicted, options_.function_tolerance);
        termination_ = text;
        return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
      }
    }
    return ceres::SOLVER_CONTINUE;
  }
  // Why the callback ended the solve (empty when it did not).
  const std::string& termination() const { return termination_; }

 private:
  const RefinementOptions& options_;
  double scale_;
  std::string termination_;
};

}  // namespace

Result<RefinementSummary> RefineByLevenbergMarquardt(
    const std::vector<TrajectoryObjective*>& objectives, const ParameterSpace& space,
    const fem::PhysicalParameters& base, double scale, std::vector<double>* x,
    const RefinementOptions& options) {
  if (objectives.empty() ||
      std::any_of(objectives.begin(), objectives.end(), [](auto* o) { return o == nullptr; })) {
    return Status::InvalidArgument("RefineByLevenbergMarquardt: no objective");
  }
  if (x == nullptr || static_cast<int>(x->size()) != space.NumVariables()) {
    return Status::InvalidArgument(
        "RefineByLevenbergMarquardt: x has " + std::to_string(x == nullptr ? 0 : x->size()) +
        " variables, the parameter space " + std::to_string(space.NumVariables()));
  }
  if (!(scale > 0.0) || !(options.jacobian_step > 0.0) || options.max_iterations < 1) {
    return Status::InvalidArgument(
        "RefineByLevenbergMarquardt: scale, jacobian_step and max_iterations must be positive");
  }
  // Ceres aborts on a residual block without residuals: no observed point in the fitted frames.
  if (objectives.front()->NumResiduals() == 0) {
    return Status::InvalidArgument(
        "RefineByLevenbergMarquardt: the fitted frames hold no observed point");
  }
  RunStatistics statistics;
  ceres::Problem problem;  // owns the cost function
  problem.AddResidualBlock(
      new ResidualFunction(objectives, space, base, scale, options.jacobian_step, &statistics),
      nullptr, x->data());
  ceres::Solver::Options solver;
  solver.minimizer_type = ceres::TRUST_REGION;
  solver.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = options.max_iterations;
  solver.function_tolerance = options.function_tolerance;
  solver.gradient_tolerance = options.gradient_tolerance;
  solver.parameter_tolerance = options.parameter_tolerance;
  solver.logging_type = ceres::SILENT;
  solver.update_state_every_iteration = true;
  IterationForwarder forwarder(options, scale);
  solver.callbacks.push_back(&forwarder);
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);

  RefinementSummary out;
  out.iterations = std::max(0, static_cast<int>(summary.iterations.size()) - 1);
  out.initial_cost = summary.initial_cost * scale;
  out.final_cost = summary.final_cost * scale;
  out.converged = summary.termination_type == ceres::CONVERGENCE ||
                  summary.termination_type == ceres::USER_SUCCESS;
  out.termination =
      summary.termination_type == ceres::USER_SUCCESS ? forwarder.termination() : summary.message;
  out.evaluations = statistics.evaluations;
  out.failed_evaluations = statistics.failed_evaluations;
  out.steps = statistics.steps;
  out.unconverged_steps = statistics.unconverged_steps;
  out.forward_seconds = statistics.forward_seconds;
  if (summary.termination_type == ceres::FAILURE || !std::isfinite(summary.initial_cost)) {
    return Status::FailedPrecondition("Levenberg-Marquardt refinement failed: " + summary.message);
  }
  return out;
}

}  // namespace softid::inverse
