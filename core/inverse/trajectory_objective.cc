#include "core/inverse/trajectory_objective.h"

#include <chrono>
#include <cmath>
#include <span>

#include "core/common/check.h"

namespace softid::inverse {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Times this close to a step (in steps) count as on it: k / fps in floating point lands within
// 1e-12 steps of k * substeps, and an interpolation weight of 1e-9 changes nothing measurable.
constexpr double kOnStepTolerance = 1e-9;

// Sums the frame costs through the loss in frame order (the same bits whichever pass computed
// them).
void SumFrameCosts(std::span<const ObservedFrame> frames, int fitted, int heldout,
                   const FrameLoss& loss, ObjectiveEvaluation* out) {
  for (size_t k = 0; k < frames.size(); ++k) {
    const double c = out->frame_costs[k];
    if (frames[k].heldout) {
      out->heldout_cost += loss.Value(c) / heldout;
    } else {
      out->cost += loss.Value(c) / fitted;
      out->reweighted_cost += loss.Weight(c) * c / fitted;
    }
  }
}

}  // namespace

TrajectoryObjective::TrajectoryObjective(const geometry::TriangleMesh& rest_mesh,
                                         const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                         const fem::PhysicalParameters& initial_parameters,
                                         fem::SimulationOptions options,
                                         const cost::SurfaceCostOptions& cost_options,
                                         std::shared_ptr<const std::vector<ObservedFrame>> frames,
                                         double fps, int substeps)
    : frames_(std::move(frames)), substeps_(substeps) {
  SOFTID_THROW_UNLESS(fps > 0.0, "fps must be positive");
  SOFTID_THROW_UNLESS(substeps >= 1, "substeps must be at least 1");
  SOFTID_THROW_UNLESS(frames_ != nullptr && !frames_->empty(), "no observed frames");
  active_frames_ = static_cast<int>(frames_->size());
  options.time_step = 1.0 / (fps * substeps);
  observation_steps_.reserve(frames_->size());
  for (const ObservedFrame& frame : *frames_) {
    SOFTID_THROW_UNLESS(std::isfinite(frame.time) && frame.time >= 0.0,
                        "observed frame times must be finite and >= 0");
    const double steps = frame.time / options.time_step;
    const double nearest = std::round(steps);
    if (std::abs(steps - nearest) <= kOnStepTolerance) {
      observation_steps_.push_back({static_cast<int>(nearest), 1.0});
    } else {
      const double upper = std::ceil(steps);
      observation_steps_.push_back({static_cast<int>(upper), 1.0 - (upper - steps)});
    }
    SOFTID_THROW_UNLESS(
        observation_steps_.size() < 2 || observation_steps_.back().step >=
                                             observation_steps_[observation_steps_.size() - 2].step,
        "observed frames must be in ascending time");
  }
  simulator_ =
      std::make_unique<fem::Simulator>(rest_mesh, initial_parameters, options, fixed_region);
  // The rest surface the simulator renders (and cameras see) is what the cost's rest SDF values
  // are fitted to.
  cost_ = std::make_unique<cost::SparseSurfaceCost>(simulator_->hex_mesh(),
                                                    simulator_->signed_distance(),
                                                    simulator_->rest_surface(), cost_options);
}

void TrajectoryObjective::SetActiveFrames(int count) {
  SOFTID_THROW_UNLESS(count >= 1 && count <= static_cast<int>(frames_->size()),
                      "active frame count " + std::to_string(count) + " outside [1, " +
                          std::to_string(frames_->size()) + "]");
  active_frames_ = count;
}

Result<ObjectiveEvaluation> TrajectoryObjective::Evaluate(const fem::PhysicalParameters& parameters,
                                                          bool with_gradient) {
  ObjectiveEvaluation out;
  const auto forward_start = std::chrono::steady_clock::now();
  SOFTID_RETURN_IF_ERROR(SimulateForward(parameters, &out));
  if (out.diverged) return out;

  const std::span<const ObservedFrame> frames(frames_->data(), active_frames_);
  int fitted = 0, heldout = 0;
  for (const ObservedFrame& frame : frames) (frame.heldout ? heldout : fitted) += 1;
  SOFTID_THROW_UNLESS(fitted > 0, "every observed frame is held out");
  out.frame_costs.resize(frames.size());
  if (!with_gradient) {
    for (size_t k = 0; k < frames.size(); ++k) {
      out.frame_costs[k] =
          cost_->Evaluate(ObservedDisplacement(static_cast<int>(k)), frames[k].points, nullptr);
    }
    SumFrameCosts(frames, fitted, heldout, frame_loss_, &out);
    out.forward_seconds = SecondsSince(forward_start);
    return out;
  }
  out.forward_seconds = SecondsSince(forward_start);

  // Each frame's cost comes with its gradient in the backward pass rather than from a second
  // evaluation in the forward pass (at one step per frame that evaluation was a large share of
  // the forward time).
  const auto backward_start = std::chrono::steady_clock::now();
  SOFTID_RETURN_IF_ERROR(Backpropagate(fitted, &out));
  SumFrameCosts(frames, fitted, heldout, frame_loss_, &out);
  out.backward_seconds = SecondsSince(backward_start);
  return out;
}

Status TrajectoryObjective::SimulateForward(const fem::PhysicalParameters& parameters,
                                            ObjectiveEvaluation* out) {
  fem::Simulator& sim = *simulator_;
  try {
    sim.SetParameters(parameters);
  } catch (const std::invalid_argument& error) {
    return Status::InvalidArgument(error.what());
  }
  const int last_step = observation_steps_[active_frames_ - 1].step;
  states_.resize(last_step + 1);
  states_[0] = sim.state();
  for (int step = 1; step <= last_step; ++step) {
    if (cancel_ != nullptr && cancel_->load(std::memory_order_relaxed)) {
      return Status::Cancelled("the simulation was cancelled");
    }
    const fem::StepSummary summary = sim.Step();
    if (summary.diverged || !sim.state().u.allFinite()) {
      out->diverged = true;
      out->steps = step;
      return Status::Ok();
    }
    if (!summary.converged) ++out->unconverged_steps;
    states_[step] = sim.state();
  }
  out->steps = last_step;
  return Status::Ok();
}

Status TrajectoryObjective::Backpropagate(int fitted, ObjectiveEvaluation* out) {
  // The cost's gradient enters at the state of each fitted frame (split between the two steps
  // around it when its time falls between them; `carry` holds the earlier step's share).
  fem::Simulator& sim = *simulator_;
  const std::span<const ObservedFrame> frames(frames_->data(), active_frames_);
  const int last_step = observation_steps_[active_frames_ - 1].step;
  const int size = static_cast<int>(states_[0].u.size());
  fem::StateAdjoint adjoint{Eigen::VectorXd::Zero(size), Eigen::VectorXd::Zero(size),
                            Eigen::VectorXd::Zero(size)};
  Eigen::VectorXd carry = Eigen::VectorXd::Zero(size);
  int next_frame = static_cast<int>(frames.size()) - 1;
  auto add_frame_gradients = [&](int step) {
    adjoint.u += carry;
    carry.setZero();
    for (; next_frame >= 0 && observation_steps_[next_frame].step == step; --next_frame) {
      const ObservedFrame& frame = frames[next_frame];
      const Eigen::VectorXd& u = ObservedDisplacement(next_frame);
      if (frame.heldout) {
        out->frame_costs[next_frame] = cost_->Evaluate(u, frame.points, nullptr);
        continue;
      }
      out->frame_costs[next_frame] = cost_->Evaluate(u, frame.points, &frame_gradient_);
      frame_gradient_ *= frame_loss_.Weight(out->frame_costs[next_frame]) / fitted;
      const Eigen::VectorXd& gradient = RestGradient(next_frame, &out->gradient);
      const double weight = observation_steps_[next_frame].weight;
      adjoint.u += weight * gradient;
      if (weight < 1.0) carry += (1.0 - weight) * gradient;
    }
  };
  for (int step = last_step; step >= 1; --step) {
    if (cancel_ != nullptr && cancel_->load(std::memory_order_relaxed)) {
      return Status::Cancelled("the adjoint pass was cancelled");
    }
    add_frame_gradients(step);
    SOFTID_RETURN_IF_ERROR(
        sim.BackpropagateStep(states_[step - 1], states_[step], &adjoint, &out->gradient));
  }
  add_frame_gradients(0);
  sim.BackpropagateInitialState(states_[0], adjoint, &out->gradient);
  return Status::Ok();
}

int TrajectoryObjective::NumResiduals() const {
  int count = 0;
  for (int k = 0; k < active_frames_; ++k) {
    const ObservedFrame& frame = (*frames_)[k];
    if (!frame.heldout) count += static_cast<int>(frame.points.size());
  }
  return count;
}

Result<ObjectiveEvaluation> TrajectoryObjective::EvaluateResiduals(
    const fem::PhysicalParameters& parameters, Eigen::VectorXd* residuals,
    ResidualWeighting weighting) {
  SOFTID_ASSIGN_OR_RETURN(ObjectiveEvaluation evaluation, Evaluate(parameters, false));
  if (evaluation.diverged) return evaluation;
  int fitted = 0;
  for (int k = 0; k < active_frames_; ++k) fitted += (*frames_)[k].heldout ? 0 : 1;
  residuals->resize(NumResiduals());
  int next = 0;
  for (int k = 0; k < active_frames_; ++k) {
    const ObservedFrame& frame = (*frames_)[k];
    if (frame.heldout || frame.points.empty()) continue;
    cost_->Evaluate(ObservedDisplacement(k), frame.points, nullptr, &matches_);
    const double c = evaluation.frame_costs[k];
    const double loss_weight = weighting == ResidualWeighting::kReweighted
                                   ? frame_loss_.Weight(c)
                                   : frame_loss_.ValueOverCost(c);
    const double weight = 2.0 * loss_weight / (static_cast<double>(fitted) * frame.points.size());
    for (const cost::PointMatch& match : matches_) {
      const double magnitude = std::sqrt(weight * match.cost);
      (*residuals)[next++] = match.matched && match.phi < 0.0 ? -magnitude : magnitude;
    }
  }
  return evaluation;
}

Result<std::vector<std::vector<cost::PointMatch>>> TrajectoryObjective::MatchPoints(
    const fem::PhysicalParameters& parameters) {
  SOFTID_ASSIGN_OR_RETURN(ObjectiveEvaluation evaluation, Evaluate(parameters, false));
  if (evaluation.diverged) return Status::FailedPrecondition("the simulation diverged");
  std::vector<std::vector<cost::PointMatch>> matches(active_frames_);
  for (int k = 0; k < active_frames_; ++k) {
    const ObservedFrame& frame = (*frames_)[k];
    cost_->Evaluate(ObservedDisplacement(k), frame.points, nullptr, &matches[k]);
  }
  return matches;
}

const Eigen::VectorXd& TrajectoryObjective::RestDisplacement(int k) {
  const ObservationStep& at = observation_steps_[k];
  if (at.weight == 1.0) return states_[at.step].u;
  observed_u_ = at.weight * states_[at.step].u + (1.0 - at.weight) * states_[at.step - 1].u;
  return observed_u_;
}

const Eigen::VectorXd& TrajectoryObjective::ObservedDisplacement(int k) {
  const fem::RestFrame& frame = simulator_->rest_frame();
  if (frame.is_identity()) return RestDisplacement(k);
  frame.DisplacementToWorld(simulator_->hex_mesh().rest_positions, RestDisplacement(k), &world_u_);
  return world_u_;
}

const Eigen::VectorXd& TrajectoryObjective::RestGradient(int k, fem::ParameterGradient* gradient) {
  // Also at the identity: d cost / d pose is wanted there (a fit of the pose starts there).
  simulator_->rest_frame().DisplacementGradientToRest(simulator_->hex_mesh().rest_positions,
                                                      RestDisplacement(k), frame_gradient_,
                                                      &rest_gradient_, gradient);
  return rest_gradient_;
}

}  // namespace softid::inverse
