// Forward simulation of a deformable body embedded in a hexahedral grid (Weiss et al. 2020, Sec.
// 3): corotated linear elasticity on cut cells, lumped mass, Rayleigh damping, implicit Newmark
// time stepping solved by Newton iterations, penalty contact with a ground plane, regularised
// Coulomb friction, air drag, a spatially varying Young's modulus and an optional clamped region.
//
// State per step is only (u, v, a) per node; element matrices depend on the parameters alone and
// rotations are recomputed from u, so the adjoint can re-run the assembly of any step from the
// stored states without storing matrices.
//
// Thread-compatibility: one Simulator per thread. Its assembly and linear solves can run on a
// team of threads of its own (SimulationOptions::threads), with results independent of their
// timing.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "core/fem/element_assembler.h"
#include "core/fem/hex_element.h"
#include "core/fem/hex_mesh.h"
#include "core/fem/linear_solver.h"
#include "core/fem/parameter_gradient.h"
#include "core/fem/physical_parameters.h"
#include "core/fem/point_forces.h"
#include "core/fem/rest_frame.h"
#include "core/fem/simulation_options.h"
#include "core/fem/step_tangent_operator.h"
#include "core/fem/surface_embedding.h"
#include "core/fem/thread_team.h"
#include "core/geometry/grid_alignment.h"
#include "core/geometry/signed_distance_field.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::fem {

// Displacement u [m], velocity v [m/s] and acceleration a [m/s^2] of every FE node (3 per node).
struct SimulationState {
  Eigen::VectorXd u, v, a;
  double time = 0.0;  // [s]
};

// Derivatives of a scalar loss with respect to a SimulationState's u, v and a (the adjoint state).
struct StateAdjoint {
  Eigen::VectorXd u, v, a;
};

struct StepSummary {
  int newton_iterations = 0;
  int linear_iterations = 0;   // summed over Newton iterations, with convergence estimates
  int tangent_assemblies = 0;  // Newton's matrix assembled (the residual alone is cheaper)
  bool converged = false;      // Newton met its tolerance
  // Non-finite state, a failed linear solve, or a body stretched past
  // SimulationOptions::max_extent_ratio: the run is invalid.
  bool diverged = false;
  bool refactorized = false;  // a renewal of the preconditioner began during this step
  double max_update = -1.0;   // last Newton update, max norm [m]
};

struct Energies {
  double kinetic = 0.0;        // [J]
  double elastic = 0.0;        // [J] (corotated: of the unrotated displacement)
  double gravitational = 0.0;  // -sum m g . x [J]
  double Total() const { return kinetic + elastic + gravitational; }
};

// The grid's axes in the rest mesh's frame (the columns; Simulator::mesh_from_grid): the mesh's
// own unless options.grid_orientation is kBody, the body is not clamped, and it has flat faces that
// the turned grid follows clearly better (SimulationOptions::kMinAlignedScore, kMinAlignmentGain).
Eigen::Matrix3d ChooseGridAxes(const geometry::TriangleMesh& rest_mesh,
                               const SimulationOptions& options, bool clamped);

class Simulator {
 public:
  // @throws std::invalid_argument naming the field when parameters or options are invalid, or when
  //   the mesh has no inside at this resolution.
  Simulator(const geometry::TriangleMesh& rest_mesh, const PhysicalParameters& parameters,
            const SimulationOptions& options,
            const std::optional<Eigen::AlignedBox3d>& fixed_region = std::nullopt);

  // The parameters as given, in the world frame (with their initial pose).
  const PhysicalParameters& parameters() const { return world_parameters_; }
  // The simulation runs in the rest mesh's frame; this carries it into the world
  // (PhysicalParameters::initial_pose). state() is in the rest frame; the positions below are in
  // the world.
  const RestFrame& rest_frame() const { return rest_frame_; }
  const SimulationOptions& options() const { return options_; }
  // The grid's frame S is the rest mesh turned by mesh_from_grid()^T about its bounding box's
  // centre (SimulationOptions::grid_orientation; the identity on a world-aligned grid): the signed
  // distance, the hex mesh, the rest surface and state() are in S. A direction d in the rest
  // mesh's coordinates is mesh_from_grid()^T d in S.
  const Eigen::Matrix3d& mesh_from_grid() const { return mesh_from_grid_; }
  const geometry::SignedDistanceField& signed_distance() const { return sdf_; }
  const HexMesh& hex_mesh() const { return mesh_; }
  // The rest surface carried by the grid (the input mesh, subdivided where coarser than the grid).
  const geometry::TriangleMesh& rest_surface() const { return surface_; }
  const SurfaceEmbedding& surface_embedding() const { return embedding_; }
  const Eigen::VectorXd& lumped_mass() const { return mass_; }  // per node [kg]
  double total_mass() const { return mass_.sum(); }
  bool is_fixed(int node) const { return fixed_[node] != 0; }
  int num_fixed_nodes() const;
  // Longest side of the rest mesh bounds in the grid's frame [m].
  double characteristic_length() const { return length_; }
  const ContactLaw& contact_law() const { return contact_; }
  // Threads the simulation runs on (SimulationOptions::threads, limited by the mesh's size).
  int num_threads() const { return team_->size(); }
  // See LinearSolver::ParallelShare.
  double solver_parallel_share() const { return solver_.ParallelShare(); }
  // Factorisations of step matrices so far (forward and adjoint passes, and new parameters).
  int num_factorizations() const { return solver_.num_factorizations(); }
  // GMRES iterations of the adjoint's transposed solves so far (BackpropagateStep).
  int backward_linear_iterations() const { return backward_linear_iterations_; }

  // Replaces the physical parameters, keeping the grid, the embedding and the surface (which
  // depend only on the rest mesh and the options), and resets to t = 0. Much cheaper than a new
  // Simulator: the optimiser calls this once per cost evaluation.
  // @throws std::invalid_argument naming the field when parameters are invalid.
  void SetParameters(const PhysicalParameters& parameters);

  const SimulationState& state() const { return state_; }
  void SetState(const SimulationState& state);
  // Back to t = 0: u = 0, v from the initial linear and angular velocity, a from the equations of
  // motion.
  void Reset();
  // Advances by one time step.
  StepSummary Step();
  // Newton solve of the static equilibrium at the current state's u (v, a set to zero). Needs a
  // clamped region or ground contact to be well posed.
  StepSummary SolveStatic();
  // The elastic stiffness matrix at rest, u = 0 [N/m]: the elements' K with the current
  // parameters (stiffness field included), without inertia, damping or surface forces; a fixed
  // node's rows and columns hold the identity. For modal analysis (elastic_modes.h). Overwrites
  // the assembly's work storage: call it before stepping or Reset() after.
  Eigen::SparseMatrix<double> RestStiffnessMatrix();

  // The step equations r(u_next) = 0 that Step() solves, from the current state to a candidate
  // end-of-step displacement u_next (v and a follow from u_next by Newmark), and their exact
  // Jacobian d r / d u_next (not symmetric: corotation; Step() may use a projected one). For the
  // adjoint and for tests.
  void EvaluateStepResidual(const Eigen::VectorXd& u_next, Eigen::VectorXd* residual,
                            Eigen::SparseMatrix<double>* jacobian);

  // Discrete adjoint of one Step() from `previous` to `next` (the state Step() produced from
  // `previous` with the current parameters). On entry `adjoint` holds dL/d(next) through every
  // later use of `next`; on return it holds dL/d(previous) through `next` (the caller adds any
  // direct dependence of L on `previous`). d L / d parameters through this step is added to
  // `gradient`. One transposed solve with the exact step Jacobian, re-assembled from the states:
  // nothing per step is stored but the states. Leaves the simulator in state `previous`.
  // The states and the adjoint are in the rest frame, and so is what this adds to `gradient`'s
  // gravity and ground until BackpropagateInitialState carries the whole gradient into the world.
  // Fails (Internal) when the transposed system cannot be solved.
  Status BackpropagateStep(const SimulationState& previous, const SimulationState& next,
                           StateAdjoint* adjoint, ParameterGradient* gradient);
  // Adjoint of Reset(): adds d L / d parameters through the initial state (its velocity from the
  // initial linear and angular velocity, its acceleration from the equations of motion), given
  // dL/d(initial state) in `adjoint`. `initial` is the state Reset() produced. Ends the backward
  // pass: carries `gradient` from the rest frame into the world and adds the initial pose's share
  // (RestFrame::ChainToWorld); d L / d pose through observed positions is the caller's
  // (RestFrame::DisplacementGradientToRest).
  void BackpropagateInitialState(const SimulationState& initial, const StateAdjoint& adjoint,
                                 ParameterGradient* gradient);

  // Deformed positions of the surface vertices in the world [m].
  std::vector<Eigen::Vector3d> SurfacePositions() const;
  geometry::TriangleMesh DeformedSurface() const;
  Energies ComputeEnergies() const;
  Eigen::Vector3d CentreOfMass() const;
  Eigen::Vector3d CentreOfMassVelocity() const;

 private:
  enum class Mode { kDynamic, kStatic };
  // Residual r(u) of the step equations and, unless residual_only, their Jacobian (into
  // assembler_.matrix(), else left as it was); v and a are the Newmark velocity and acceleration
  // implied by u. Returns the body rotation.
  // reuse_rotations: element_rotation_ already holds the rotations at this u (the previous
  // assembly was at the same u), so the polar decompositions are skipped.
  Eigen::Matrix3d Assemble(Mode mode, const Eigen::VectorXd& u, const Eigen::VectorXd& v,
                           const Eigen::VectorXd& a, bool residual_only = false,
                           bool reuse_rotations = false);
  // Assemble for a dynamic step from state_ to the end-of-step (u, v, a): elastic, damping and
  // inertial forces at the generalized-alpha point (u_f, v_f, a_m), kept in step_u_, step_v_,
  // step_a_ (the arguments themselves under plain Newmark); surface forces (contact, friction,
  // drag) at the end of the step, (u, v). Friction at v_f would hold v_f at zero in stick, so
  // the end velocity would flip sign every step (v' = -alpha_f / (1 - alpha_f) v): a block on a
  // shallow ramp crept at 9x its creep speed. The residual is r; the matrix is
  // (dr/du) / (1 - alpha_f), Assemble scaling the inertia and surface terms accordingly.
  Eigen::Matrix3d AssembleStep(const Eigen::VectorXd& u, const Eigen::VectorXd& v,
                               const Eigen::VectorXd& a, bool residual_only = false,
                               bool reuse_rotations = false);
  bool UsesGeneralizedAlpha() const {
    return options_.generalized_alpha_m != 0.0 || options_.generalized_alpha_f != 0.0;
  }
  // The generalized-alpha evaluation point of the last AssembleStep.
  const Eigen::VectorXd* step_u_ = nullptr;
  const Eigen::VectorXd* step_v_ = nullptr;
  const Eigen::VectorXd* step_a_ = nullptr;
  Eigen::VectorXd alpha_u_, alpha_v_, alpha_a_;
  // Where Assemble evaluates the surface forces when not at its (u, v) (generalized-alpha: the
  // end of the step), and the factor of their Jacobian blocks, 1 / (1 - alpha_f).
  const Eigen::VectorXd* surface_u_ = nullptr;
  const Eigen::VectorXd* surface_v_ = nullptr;
  double surface_jacobian_scale_ = 1.0;
  // Coefficients of one assembly shared by all elements and surface points.
  struct AssemblyTerms {
    bool dynamic = false;
    bool jacobian = true;          // assemble the tangent blocks too
    bool reuse_rotations = false;  // element_rotation_ is current
    // Keep what StepTangentOperator needs beyond the rotations: the point Jacobians (also in a
    // residual-only assembly) and the coefficients.
    bool record_tangent = false;
    double stiffness_damping = 0.0;      // beta_k, applied when dynamic
    double stiffness_coefficient = 1.0;  // of R K R^T in the tangent
    double mass_coefficient = 0.0;       // of the lumped mass in the tangent
    double dv_du = 0.0;                  // d v / d u of the Newmark update [1/s], 0 when static
  };
  AssemblyTerms MakeAssemblyTerms(Mode mode, bool residual_only, bool reuse_rotations) const;
  // The stages of Assemble, in order (core/fem/simulator_assembly.cc).
  void BeginAssembly(const AssemblyTerms& terms);
  Eigen::Matrix3d AssembleElements(const AssemblyTerms& terms, const Eigen::VectorXd& u,
                                   const Eigen::VectorXd& v);  // returns sum V_e R_e
  void AssembleInertiaAndGravity(const AssemblyTerms& terms, const Eigen::VectorXd& v,
                                 const Eigen::VectorXd& a);
  void AssembleSurfaceForces(const AssemblyTerms& terms, const Eigen::VectorXd& u,
                             const Eigen::VectorXd& v);
  void EliminateFixedNodes(const AssemblyTerms& terms);
  // One element's force (into residual_), tangent blocks (into assembler_) and rotation (into
  // element_rotation_). Touches only the element's own nodes, so elements sharing no node may be
  // assembled concurrently.
  void AssembleElement(int e, const AssemblyTerms& terms, const Eigen::VectorXd& u,
                       const Eigen::VectorXd& v);
  // An element's corotated state at (u, v), its stages (simulator_assembly.cc).
  struct CorotatedElement;
  void CorotateElement(int e, const AssemblyTerms& terms, const Eigen::VectorXd& u,
                       const Eigen::VectorXd& v, CorotatedElement* element);
  bool GeometricTangentTerm(int e, const AssemblyTerms& terms, const CorotatedElement& element,
                            const std::array<Eigen::Matrix3d, 64>& stiffness,
                            std::array<Eigen::Matrix3d, 8>* w,
                            std::array<Eigen::Matrix3d, 8>* q) const;
  // One surface point's contact, friction and drag force (into residual_) and tangent blocks (into
  // assembler_), at (surface_u, surface_v). Touches only the nodes of the point's element.
  void AssembleSurfacePoint(int p, const AssemblyTerms& terms, const Eigen::VectorXd& surface_u,
                            const Eigen::VectorXd& surface_v);
  // Largest fraction of a Newton update (<= 1) that keeps every surface point above
  // min(its distance, 0) - 4 contact smoothing lengths.
  double ContactStepLimit(const Eigen::VectorXd& u, const Eigen::VectorXd& update) const;
  // Largest fraction of a Newton update (<= 1) that reverses no contact point's slip by more than
  // 4 friction velocity scales.
  double FrictionStepLimit(const Eigen::VectorXd& v, const Eigen::VectorXd& update) const;
  void NewmarkKinematics(const Eigen::VectorXd& u, Eigen::VectorXd* v, Eigen::VectorXd* a) const;
  Eigen::VectorXd InitialAcceleration(const Eigen::VectorXd& v);
  // Mass, element stiffness and contact law from parameters_; refactorises the reference.
  void ApplyParameters();
  void BuildMassAndStiffness();
  void AddLumpedMass(int e);
  void SetUpSurfaceForces();
  void FactorizeReference();
  // The constructor's stages: the hex grid from the rest mesh's signed distance, the embedded
  // surface, the assembly's threads and their element and surface-point ranges.
  geometry::TriangleMesh TurnedIntoGrid(const geometry::TriangleMesh& rest_mesh) const;
  // Element e's centre in the rest mesh's coordinates (where a StiffnessField is given).
  Eigen::Vector3d ElementCentreInMesh(int e) const;
  void BuildGrid(const geometry::TriangleMesh& rest_mesh,
                 const std::optional<Eigen::AlignedBox3d>& fixed_region);
  void EmbedSurface(const geometry::TriangleMesh& rest_mesh);
  int AssemblyThreads() const;
  void PartitionElements();
  void AssignSurfacePointsToChunks();
  // The adjoint of the step residual r(u, v, a; u_previous, parameters) (u_previous enters through
  // the lagged friction normal force) for multiplier lambda: sets velocity_adjoint = (dr/dv)^T
  // lambda and previous_adjoint = -(dr/du_previous)^T lambda, and adds -lambda^T dr/dparameters
  // to `gradient`. (dr/da)^T lambda is M lambda. rotations_current: element_rotation_ holds the
  // rotations at u (an assembly at u came last), which are then not recomputed.
  // The surface forces are evaluated at `surface` (u, v) when given (generalized-alpha: the end
  // of the step); their velocity adjoint then goes to surface->velocity_adjoint, and
  // surface->jacobian_adjoint receives (dr_s/du + dv_du dr_s/dv)^T lambda, their share of the
  // step matrix (unscaled).
  struct SurfaceAdjoint {
    const Eigen::VectorXd* u = nullptr;
    const Eigen::VectorXd* v = nullptr;
    Eigen::VectorXd velocity_adjoint;
    Eigen::VectorXd jacobian_adjoint;
  };
  void ResidualAdjoint(const Eigen::VectorXd& u, const Eigen::VectorXd& v, const Eigen::VectorXd& a,
                       const Eigen::VectorXd& u_previous, const Eigen::VectorXd& lambda,
                       Eigen::VectorXd* velocity_adjoint, Eigen::VectorXd* previous_adjoint,
                       ParameterGradient* gradient, bool rotations_current = false,
                       SurfaceAdjoint* surface = nullptr);
  struct ResidualAdjointPass;  // ResidualAdjoint's stages (simulator_adjoint.cc)
  struct AdjointStep;          // BackpropagateStep's stages (simulator_adjoint.cc)
  // Per element d K / d mu (ElementShearDerivative), without the stiffness field's scale (it does
  // not depend on it): d K / d poisson_ratio needs it. Built on the first backward pass after the
  // parameters are applied.
  void BuildShearStiffness();
  std::vector<Matrix24d, Eigen::aligned_allocator<Matrix24d>> shear_matrices_;
  std::vector<int> element_shear_index_;  // into shear_matrices_, per element
  const Matrix24d& ShearStiffnessOf(int e) const {
    return shear_matrices_[element_shear_index_[e]];
  }
  std::vector<std::array<double, 8>> element_stiffness_weights_;
  std::vector<double> element_scale_;  // stiffness field scale per element
  StepSummary NewtonSolve(Mode mode);
  struct NewtonRun;  // NewtonSolve's stages and the state they share (simulator.cc)
  // Whether the next dynamic step first tries the preconditioner's estimate as its only update:
  // after a step that converged with one Newton update. Reset with the state, so a run depends on
  // its start alone.
  bool estimate_first_ = false;
  // Whether the matrix Newton assembles in this mode is symmetric up to round-off (see
  // LinearSolver::Symmetry).
  LinearSolver::Symmetry TangentSymmetry(Mode mode) const;

  // parameters_ is what the physics uses: world_parameters_ in the rest frame (rest_frame.h).
  PhysicalParameters world_parameters_;
  PhysicalParameters parameters_;
  RestFrame rest_frame_;
  Eigen::Vector3d pose_centre_ = Eigen::Vector3d::Zero();  // rest mesh's bounding-box centre [m]
  Eigen::Matrix3d mesh_from_grid_ = Eigen::Matrix3d::Identity();
  SimulationOptions options_;
  double length_ = 0.0;
  // Diagonal of the FE nodes' rest bounding box [m] (the divergence test's yardstick).
  double rest_extent_ = 0.0;
  // Whether the body at displacement u spans more than options_.max_extent_ratio x rest_extent_.
  bool ExceedsExtent(const Eigen::VectorXd& u) const;
  geometry::SignedDistanceField sdf_;
  HexMesh mesh_;
  geometry::TriangleMesh surface_;
  SurfaceEmbedding embedding_;        // rendering: follows the grid, extrapolating
  SurfaceEmbedding force_embedding_;  // contact and drag: clamped into the elements
  std::vector<double> surface_areas_;
  // Contact normal force per surface point at the start of the step (for lagged friction); a
  // function of u_n, so it is recomputed, not part of the state.
  std::vector<double> lagged_normal_force_;
  void UpdateLaggedNormalForces();
  // Newton's friction force estimate per surface point (see GroundContactForce), used for the
  // forward tangent only: set from v_n at the start of a step, advanced by the linearised
  // friction law after each update and kept within the friction cone. Not part of the state: the
  // converged step does not depend on it.
  std::vector<Eigen::Vector3d> friction_iterate_;
  bool use_friction_iterate_ = false;
  Eigen::VectorXd v_before_;  // work storage of the Newton update
  void AdvanceFrictionIterate(const Eigen::VectorXd& v, const Eigen::VectorXd& dv);
  // Element stiffness matrices, one per distinct (octant weights, stiffness scale): every full
  // cell of a uniform body shares one. Streaming a 4.6 KB matrix per element dominated the
  // assembly's memory traffic; a shared one stays in cache, and each distinct matrix is built
  // once per SetParameters.
  std::vector<Matrix24d, Eigen::aligned_allocator<Matrix24d>> stiffness_matrices_;
  std::vector<int> element_stiffness_index_;  // into stiffness_matrices_, per element
  const Matrix24d& StiffnessOf(int e) const {
    return stiffness_matrices_[element_stiffness_index_[e]];
  }
  std::vector<Eigen::Matrix3d> element_rotation_;
  // Parallel element loop of Assemble: the elements are cut into one contiguous range (a slab of
  // the grid) per thread; thread t assembles the elements of range t that share no node with
  // another range (element_chunks_[t], ascending), then one thread the rest (shared_elements_,
  // ascending). Writes of different threads never overlap and every matrix and residual entry is
  // summed in a fixed order, whatever the thread timing.
  std::vector<std::vector<int>> element_chunks_;
  std::vector<int> shared_elements_;
  // Surface points (force_embedding_) likewise, by their element: points of range t's own
  // elements (ascending), and those of shared elements.
  std::vector<std::vector<int>> point_chunks_;
  std::vector<int> shared_points_;
  // Newton's matrix-free tangent (SimulationOptions::matrix_free_newton): while record_tangent_,
  // every assembly keeps the surface points' step Jacobians (where they act) and the tangent's
  // coefficients, which with element_rotation_ are all StepTangentOperator reads.
  bool record_tangent_ = false;
  std::vector<Eigen::Matrix3d> point_jacobians_;
  std::vector<char> point_active_;
  double tangent_stiffness_coefficient_ = 1.0;
  double tangent_mass_coefficient_ = 0.0;
  StepTangentOperator::Views TangentViews();
  StepTangentOperator step_tangent_;  // bound to TangentViews() for each solve
  // SimulationOptions::contact_correction: the nodes of the elements holding a surface point whose
  // recorded step Jacobian is comparable to its inertia there (contact and friction, not air drag),
  // ascending, clamped nodes left out; none with the option off. Kept in contact_nodes_, which the
  // next call overwrites.
  const std::vector<int>& ContactNodes();
  std::vector<char> contact_member_;  // work storage of ContactNodes, per node
  std::vector<int> contact_nodes_;
  // The team running the parallel loops (one member per element chunk), shared with solver_;
  // declared before solver_, which must finish its background work on it before it goes.
  std::unique_ptr<ThreadTeam> team_;
  Eigen::VectorXd mass_;
  std::vector<char> fixed_;
  ContactLaw contact_;
  bool has_surface_forces_ = false;

  // Assemble Newton's tangent: without the geometric term in dynamic steps, and in static solves
  // without an element's stress-stiffness term where it would make the element's block
  // indefinite. EvaluateStepResidual and the adjoint turn this off for the exact Jacobian.
  bool newton_tangent_ = true;

  ElementAssembler assembler_;
  LinearSolver solver_;
  // The last adjoint solution lambda of a backward pass: the next (earlier) step's initial guess,
  // since lambda changes little from step to step. Cleared by BackpropagateInitialState.
  Eigen::VectorXd adjoint_guess_;
  // The factors the forward steps were solved with, each from the time of the step it became
  // current at (ascending). The adjoint pass preconditions each step with the factor its forward
  // step used (its transposed exact Jacobian is near the forward's tangent), instead of
  // refactorising where that one went stale. A null factor: not kept (the history's memory
  // reached kFactorHistoryBytes); the adjoint then keeps its own. A step taken from an earlier
  // time drops what came after it; new parameters clear it.
  struct FactorUse {
    double time = 0.0;  // [s]
    std::shared_ptr<LinearSolver::FactorSnapshot> factor;
  };
  std::vector<FactorUse> factor_history_;
  size_t factor_history_bytes_ = 0;
  // The history entry the adjoint pass has made current (its time), NaN after a forward step.
  double backward_factor_time_ = std::numeric_limits<double>::quiet_NaN();
  // Whether a pending factorisation (LinearSolver::StartFactorize) was begun by the adjoint pass;
  // one the forward pass left pending is dropped when the adjoint reuses the forward's factors.
  bool backward_factorization_pending_ = false;
  int backward_linear_iterations_ = 0;
  void RecordFactor();
  void UseForwardFactor(double step_start_time);
  SimulationState state_;
  // Work vectors of the Newton iteration.
  Eigen::VectorXd residual_, rhs_, update_, u_next_, v_next_, a_next_;
};

}  // namespace softid::fem
