// Screening the candidate extensions at the base fit, before any costly refit: Rao's score test
// with the base parameters profiled out.
//
// Each candidate (variant) is reduced to one new variable theta along which it leaves its null:
// friction mu, drag c2, the log of the stiffness ratio of two halves along x, y or z (three
// variants), the log of the contact stiffness, the spin rate along the direction the gradient
// points. The adjoint gives g = dC/dtheta at the null (the score) and, one run at theta = delta
// later, the curvature H_tt and the cross-curvature h = d(dC/dx_b)/dtheta with the base variables
// x_b. With the base Hessian H_bb (identifiability analysis of the base fit) the efficient
// curvature is the Schur complement
//   H_eff = H_tt - h^T H_bb^-1 h,
// i.e. the curvature left once the base parameters re-adjust (a drag partly absorbed by a slower
// throw, friction partly by a stiffer body). Predicted cost drop: g^2 / (2 H_eff), at
// theta* = -g / H_eff with the base at x_b - H_bb^-1 h theta*; the predicted LR follows
// (likelihood_ratio.h). The refit starts from the best (forward cost) of that step, the extension
// alone at theta*, and a ladder of the extension alone over its start range (1/16 ... 3/4 of it):
// large effects are far from quadratic (stick-slip; a cube spinning looks alike every quarter
// turn). Two-sided variables (stiffness ratio, contact stiffness) are laddered on both sides of the
// null: a large effect's minimum can lie against the slope at the null; the best start of each side
// at least a factor 2 from the null is kept (the refit runs from both). The stiffness ladder keeps
// the geometric mean of the halves' moduli at the base fit's E when E is fitted: the base fit found
// the body's average stiffness, and a start that also changed it would rate the contrast by a wrong
// mean. The spin is laddered also both ways along the body's principal axes (PrincipalAxes): the
// score's direction is the linear response of the first frames, mixes in other axes and can even
// have the wrong sign. A boundary parameter whose score says "the cost rises as it leaves 0" is
// dropped: the one-sided test has nothing to offer. Signature: the share of the base fit's excess
// misfit (above the noise floor) in the phases where the extension acts (candidate_library.h).
// score = predicted LR x ((1 - w) + w x share).
#pragma once

#include <Eigen/Core>
#include <array>
#include <limits>
#include <vector>

#include "core/common/status.h"
#include "core/diagnosis/candidate_library.h"
#include "core/diagnosis/motion_phases.h"
#include "core/fem/hex_mesh.h"
#include "core/fem/physical_parameters.h"
#include "core/inverse/objective_pool.h"
#include "core/inverse/parameter_space.h"
#include "core/inverse/trajectory_objective.h"

namespace softid::diagnosis {

struct ScreeningOptions {
  // delta, the step of the curvature run in each extension's variable: small against the values
  // that matter (mu ~ 0.1, drag ~ 0.6 kg/m^3, a 2x stiffness ratio), large against the cost's
  // piecewise-smooth wrinkles. Units: mu [-], drag [kg/m^3], log ratio, log k, spin [rad/s].
  double friction_step = 0.02;
  double drag_step = 0.05;
  double log_ratio_step = 0.1;
  double log_contact_step = 0.1;
  double spin_step = 0.2;
  // Refit starts are clamped to these bounds of theta* (the plausible ranges, trimmed: a start
  // far out makes a long way back for the optimiser).
  double max_friction_start = 0.8;
  double max_drag_start = 3.0;
  double max_log_ratio_start = 2.3;  // ratio 10
  double max_log_contact_start = 3.0;
  double max_spin_start = 10.0;  // [rad/s]
  // Refit starts of two-sided variables lie at least this factor from the null (ratio or
  // stiffness x or / it) [-], > 1. 2: past the plausibility gate's "uniform" band [0.8, 1.25]
  // with room, and still inside the basin of a contrast of 1.5 or of 5.
  double two_sided_start_factor = 2.0;
  // Weight w of the signature share in the score [-], in [0, 1].
  double signature_weight = 0.75;
  Status Validate() const;
};

struct ScreenedCandidate {
  Extension extension = Extension::kFriction;
  int axis = -1;  // heterogeneous_stiffness: the split axis of this variant
  bool applicable = true;
  std::string note;                  // why not applicable, or what the score said
  double gradient = 0.0;             // g = dC/dtheta at the null [m^2 / unit of theta]
  double curvature = 0.0;            // H_tt [m^2 / unit^2]
  double efficient_curvature = 0.0;  // H_eff
  double theta = 0.0;                // theta of the refit start
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();  // spin axis (initial_spin)
  double start_cost = 0.0;                              // forward cost at the refit start [m^2]
  fem::PhysicalParameters start;  // the refit start (base variables moved too)
  // The refit's starts: {start}, or for a two-sided variable (stiffness ratio, contact
  // stiffness) the best start on each side of the null at least two_sided_start_factor from it
  // (the refit runs from both, the lower fitted cost wins). Next to the null both sides look
  // alike at the base parameters (the base fit absorbed what a small change does), and from there
  // the optimiser slides into the nearer side's local minimum: a 4x stiffness contrast refitted
  // from ratios 0.75 and 1.15 ended at 0.79 both times.
  std::vector<fem::PhysicalParameters> refit_starts;
  std::vector<double> refit_thetas;  // theta of each
  // Further screened points on the start's side of the null, lowest forward cost first (at most
  // kMaxFallbackStarts): the refit runs from them only when every refit start fails (a forward
  // pass can succeed where the adjoint or a first Newton step cannot).
  std::vector<fem::PhysicalParameters> fallback_starts;
  static constexpr int kMaxFallbackStarts = 2;
  double predicted_lr = 0.0;
  double signature_share = 0.0;  // [0, 1]
  double score = 0.0;
};

// Per observed frame, whether the extension's signature covers it (motion aligned with frames).
std::vector<bool> SignatureFrames(const Candidate& candidate,
                                  const std::vector<FrameMotion>& motion);

// The base model around which candidates are screened.
struct ScreeningBase {
  fem::PhysicalParameters parameters;              // the base fit
  std::vector<std::string> fitted;                 // its canonical fitted names
  const inverse::ParameterSpace* space = nullptr;  // of `fitted` at `parameters`
  Eigen::MatrixXd hessian;  // H_bb in space's variables [m^2]; empty: base not profiled out
  double cost = 0.0;        // C0 [m^2]
  double n_eff = 0.0;
  double floor_cost = 0.0;  // sigma^2 / 2, the cost of a perfect model [m^2]
  Eigen::AlignedBox3d rest_bounds;
  // Builds objectives like the screened one (frames, grid, time step, cost) for the variants'
  // slope runs and their refit tries, which then run `workers` at a time, each worker on an
  // objective of its own (the null stays on the screened objective). Objectives with one
  // simulation thread make the screening the same whatever the number of workers. Empty: every
  // run one after another on the screened objective.
  inverse::ObjectiveFactory make_objective;
  int workers = 1;  // >= 1
};

// Screens every candidate of CandidateLibrary() (the stiffness split once per axis) around
// `base`. @param excess per observed frame, max(0, misfit^2 - sigma^2) [m^2]. Results are sorted by
// score, best first. FailedPrecondition when the base simulation diverges; adjoint errors are
// passed on.
Result<std::vector<ScreenedCandidate>> ScreenCandidates(inverse::TrajectoryObjective& objective,
                                                        const ScreeningBase& base,
                                                        const std::vector<FrameMotion>& motion,
                                                        const std::vector<double>& excess,
                                                        const ScreeningOptions& options = {});

// Principal axes of the rest body's volume (unit vectors, world frame), by increasing second
// moment; where two moments agree within 5 % (a cube, a bar of square section) the world axes
// projected into their plane. The initial-spin screening tries a start along each.
std::array<Eigen::Vector3d, 3> PrincipalAxes(const fem::HexMesh& mesh);

}  // namespace softid::diagnosis
