// The function the optimiser minimises: simulate from t = 0 with given parameters, compare every
// fitted frame with what the cameras saw through the sparse-surface-constraint cost, and get the
// gradient with respect to every parameter by one adjoint pass backwards through the states.
//
//   cost = (1 / F) sum over the F fitted frames k of L(C_k(u(t_k)))   [m^2]
//
// L is the frame loss (frame_loss.h; least squares, L(c) = c, unless SetFrameLoss says
// otherwise). C_k is the per-frame SSC cost (mean truncated squared distance of the frame's
// points); frame k is compared with the state at its time t_k (k / fps, or the capture's
// frame_times): the state after t_k / dt steps when t_k falls on a step, else the linear
// interpolation of the two steps around it (jittered or dropped frames). Held-out frames are
// evaluated (for validation) but do not enter the cost or the gradient. Only the active frames (a
// prefix, by default all) are simulated and compared.
//
// Memory: the states (u, v, a) of every step, nothing else; matrices are re-assembled backwards.
// Thread-compatibility: one instance per thread (it owns a Simulator and a cost).
#pragma once

#include <Eigen/Geometry>
#include <atomic>
#include <memory>
#include <optional>
#include <vector>

#include "core/common/status.h"
#include "core/cost/sparse_surface_cost.h"
#include "core/fem/parameter_gradient.h"
#include "core/fem/physical_parameters.h"
#include "core/fem/simulation_options.h"
#include "core/fem/simulator.h"
#include "core/geometry/triangle_mesh.h"
#include "core/inverse/frame_loss.h"
#include "core/inverse/observed_frames.h"

namespace softid::inverse {

struct ObjectiveEvaluation {
  bool diverged = false;      // the forward run failed: no cost, the parameters are unusable
  double cost = 0.0;          // mean of L(C_k) over fitted frames [m^2]
  double heldout_cost = 0.0;  // mean of L(C_k) over held-out frames [m^2] (0 without any)
  // mean of L'(C_k) C_k over fitted frames [m^2]: the cost of the reweighted least-squares
  // problem at these parameters (1/2 |r|^2 of EvaluateResiduals); = cost with least squares.
  double reweighted_cost = 0.0;
  std::vector<double> frame_costs;  // C_k per active observed frame (fitted and held out) [m^2]
  fem::ParameterGradient gradient;  // d cost / d parameters (when requested)
  int steps = 0;
  // Steps whose Newton iteration stopped at max_newton_iterations short of its tolerance: the
  // state then depends on the iteration path, so the cost is not smooth in the parameters there.
  int unconverged_steps = 0;
  double forward_seconds = 0.0, backward_seconds = 0.0;
};

class TrajectoryObjective {
 public:
  // @param frames observed frames, ascending, shared read-only between objectives (starts).
  // @param options simulation options; time_step is replaced by 1 / (fps * substeps).
  // @throws std::invalid_argument naming the field for invalid options (as Simulator).
  TrajectoryObjective(const geometry::TriangleMesh& rest_mesh,
                      const std::optional<Eigen::AlignedBox3d>& fixed_region,
                      const fem::PhysicalParameters& initial_parameters,
                      fem::SimulationOptions options, const cost::SurfaceCostOptions& cost_options,
                      std::shared_ptr<const std::vector<ObservedFrame>> frames, double fps,
                      int substeps);

  // Forward run, cost and (if with_gradient) the adjoint gradient. A diverging forward run is
  // reported as diverged (never as a shorter run with a lower cost). Internal error when an
  // adjoint solve fails.
  Result<ObjectiveEvaluation> Evaluate(const fem::PhysicalParameters& parameters,
                                       bool with_gradient);

  // The cost as a sum of squares, for Gauss-Newton methods: one residual per observed point of
  // every fitted active frame k (N_k points, F fitted frames), in frame order,
  //   r = sign(phi) sqrt(2 w_k rho(phi) / (F N_k))   [m],   so that cost = 1/2 |r|^2
  // with least squares (w_k = 1). With another frame loss, `weighting` chooses w_k (below).
  // sign(phi) keeps r smooth through phi = 0 (rho ~ phi^2 / 2 there); a point matching nothing
  // (constant rho) counts as outside. Forward only; `residuals` is resized to NumResiduals().
  // The evaluation's cost and frame costs are filled as by Evaluate(parameters, false).
  enum class ResidualWeighting {
    // w_k = L'(C_k): 1/2 |r|^2 is the reweighted least-squares problem at these parameters (equal
    // gradient, not equal value): the curvature and noise scale of the uncertainty analysis.
    kReweighted,
    // w_k = L(C_k) / C_k: 1/2 |r|^2 is the cost itself, as a smooth function of the parameters,
    // so that a trust-region method (Levenberg-Marquardt) compares steps by the cost it minimises.
    kLossValue,
  };
  Result<ObjectiveEvaluation> EvaluateResiduals(
      const fem::PhysicalParameters& parameters, Eigen::VectorXd* residuals,
      ResidualWeighting weighting = ResidualWeighting::kReweighted);
  // Number of residuals of EvaluateResiduals at the current active frames.
  int NumResiduals() const;

  // Per observed frame, the point matches at the given parameters (diagnosis); runs forward only.
  Result<std::vector<std::vector<cost::PointMatch>>> MatchPoints(
      const fem::PhysicalParameters& parameters);

  // Horizon: only the first `count` observed frames are simulated and compared (fitted and held
  // out alike); the default is every frame. The optimiser's continuation over the horizon
  // (fit.cc) fits a prefix first. @pre 1 <= count <= frames().size(), with a fitted frame.
  void SetActiveFrames(int count);
  int active_frames() const { return active_frames_; }

  // Checked every simulation step of Evaluate and EvaluateResiduals, forward and backward: when
  // set, they return StatusCode::kCancelled within one step (a cancel takes effect within
  // seconds even inside a long run). Null (default): never cancelled.
  void SetCancelFlag(const std::atomic<bool>* cancel) { cancel_ = cancel; }
  // How frame costs add up (default least squares). EvaluateResiduals then weights frame k's
  // residuals by sqrt(loss.Weight(C_k)) (the Gauss-Newton form of the reweighted problem).
  void SetFrameLoss(const FrameLoss& loss) { frame_loss_ = loss; }
  const FrameLoss& frame_loss() const { return frame_loss_; }

  fem::Simulator& simulator() { return *simulator_; }
  const std::vector<ObservedFrame>& frames() const { return *frames_; }
  int substeps() const { return substeps_; }
  double characteristic_length() const { return simulator_->characteristic_length(); }

 private:
  std::unique_ptr<fem::Simulator> simulator_;
  std::unique_ptr<cost::SparseSurfaceCost> cost_;
  std::shared_ptr<const std::vector<ObservedFrame>> frames_;
  int substeps_ = 1;
  int active_frames_ = 0;
  // Where observed frame k meets the simulation: the state weight * u[step] + (1 - weight) *
  // u[step - 1], weight in (0, 1]; weight 1 when t_k falls on step `step`.
  struct ObservationStep {
    int step = 0;
    double weight = 1.0;
  };
  // The simulated displacement at observed frame k in the rest frame (a state, or `observed_u_`
  // interpolated), and in the world (the initial pose applied; the same vector without one).
  const Eigen::VectorXd& RestDisplacement(int k);
  const Eigen::VectorXd& ObservedDisplacement(int k);
  // frame_gradient_ (d cost / d world displacement at frame k) in the rest frame, adding d cost /
  // d initial pose through it to *gradient.
  const Eigen::VectorXd& RestGradient(int k, fem::ParameterGradient* gradient);
  // Evaluate's passes. The forward run from t = 0 into states_ (steps and unconverged steps into
  // *out; out->diverged when it fails). The adjoint pass back through states_: every active
  // frame's cost into out->frame_costs and d cost / d parameters into out->gradient, for
  // `fitted` fitted frames.
  Status SimulateForward(const fem::PhysicalParameters& parameters, ObjectiveEvaluation* out);
  Status Backpropagate(int fitted, ObjectiveEvaluation* out);

  std::vector<ObservationStep> observation_steps_;  // per observed frame
  std::vector<fem::SimulationState> states_;        // per step, reused across evaluations
  Eigen::VectorXd observed_u_;                      // scratch of ObservedDisplacement
  Eigen::VectorXd world_u_;                         // scratch of ObservedDisplacement
  Eigen::VectorXd frame_gradient_;                  // d frame cost / d world displacement
  Eigen::VectorXd rest_gradient_;                   // the same in the rest frame
  std::vector<cost::PointMatch> matches_;           // scratch of EvaluateResiduals
  const std::atomic<bool>* cancel_ = nullptr;
  FrameLoss frame_loss_;
};

}  // namespace softid::inverse
