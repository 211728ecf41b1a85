#include "core/fem/simulator.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <stdexcept>
#include <thread>
#include <utility>

#include "core/common/check.h"
#include "core/fem/corotation.h"
#include "core/fem/hex_element.h"

namespace softid::fem {
namespace {

void ThrowIfError(const Status& status) {
  if (!status.ok()) throw std::invalid_argument(status.message());
}

// y = blockdiag(R) x for a 24-vector.
Vector24d RotateCorners(const Eigen::Matrix3d& r, const Vector24d& x) {
  Vector24d y;
  for (int c = 0; c < 8; ++c) y.segment<3>(3 * c).noalias() = r * x.segment<3>(3 * c);
  return y;
}

// Threads of a simulation's team: at most this many, and only on meshes large enough that a
// parallel region outweighs waking them and the elements shared between the assembly's ranges
// (run by one thread) are few.
constexpr int kMaxSimulationThreads = 4;
constexpr int kMinElementsPerThread = 256;

// A background factorisation (~100 ms at 3,100 cells) is adopted at a step start once the solves
// since have done about its work, and after at most this many steps. Adopting at the next step
// start made that step wait ~100 ms with one core idle (torus-drop's impact, 3,100 cells); the
// old factor serving a step or two longer costs a few GMRES iterations.
constexpr int kMaxFactorizationSteps = 3;

// Newton's tolerance on the velocity update under friction, as a fraction of the friction
// velocity scale. A block sliding on a 30 degree ramp (mu = 0.3, 8 cells, 0.4 s) ends 1 um from a
// fully converged run with updates below 1e-5 h (0.06 velocity scales), but 70-120 um with
// 1e-4 h (0.6): the stick-slip law amplifies velocity errors as position errors are not.
constexpr double kFrictionVelocityTolerance = 0.05;

// GMRES iterations a solve may take on the plain factor before it switches to the contact
// correction (SimulationOptions::contact_correction) for the rest of the step. The correction's
// setup, the contact nodes' rows and their sparse LU, costs about 2-5 plain iterations per Newton
// iteration (cube on a ramp, 16 cells: ~1.3 ms beside ~1 ms per iteration; pillow-ramp ~4.5 ms):
// it pays in a friction landing (~30 iterations per solve on a factor a few iterations old, ~5
// corrected), not on a body resting or sliding (2-5 iterations, which it made 2-3x slower).
constexpr int kPlainIterationsBeforeCorrection = 10;

// Splits the elements among `threads` ranges (range_of[e]): per range the elements that share no
// node with another range (ascending), and the rest, which touch two ranges (ascending).
std::pair<std::vector<std::vector<int>>, std::vector<int>> SplitElements(
    const HexMesh& mesh, const std::vector<int>& range_of, int threads) {
  constexpr int kUntouched = -1, kShared = -2;
  std::vector<int> node_range(mesh.NumNodes(), kUntouched);
  const int num_elements = mesh.NumElements();
  for (int e = 0; e < num_elements; ++e) {
    for (int node : mesh.element_nodes[e]) {
      int& owner = node_range[node];
      if (owner == kUntouched)
        owner = range_of[e];
      else if (owner != range_of[e])
        owner = kShared;
    }
  }
  std::vector<std::vector<int>> chunks(threads);
  std::vector<int> shared;
  for (int e = 0; e < num_elements; ++e) {
    const bool own = std::all_of(mesh.element_nodes[e].begin(), mesh.element_nodes[e].end(),
                                 [&](int node) { return node_range[node] == range_of[e]; });
    (own ? chunks[range_of[e]] : shared).push_back(e);
  }
  return {std::move(chunks), std::move(shared)};
}

// Least share of an element's mass a corner gets, as a fraction of the uniform share V_e / 8.
constexpr double kMinNodeMassShare = 0.25;

// Per axis, the face of the fixed region that cuts through the body (NaN where none does): the
// grid puts a plane of nodes on it, so that the clamped length is the region's at every
// resolution. Holding the nodes inside the region otherwise clamps up to the last node plane
// inside, which moves with the grid: a bar clamped over 2 cm was held over 2 cm at 24 and 48
// cells and 1.5 cm at 32, and its fitted modulus followed (docs/benchmarks.md).
Eigen::Vector3d ClampFacePlanes(const Eigen::AlignedBox3d& fixed_region,
                                const Eigen::AlignedBox3d& body) {
  Eigen::Vector3d planes = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  for (int a = 0; a < 3; ++a) {
    const auto cuts = [&](double face) { return face > body.min()[a] && face < body.max()[a]; };
    if (cuts(fixed_region.max()[a])) {
      planes[a] = fixed_region.max()[a];
    } else if (cuts(fixed_region.min()[a])) {
      planes[a] = fixed_region.min()[a];
    }
  }
  return planes;
}

}  // namespace

Eigen::Matrix3d ChooseGridAxes(const geometry::TriangleMesh& rest_mesh,
                               const SimulationOptions& options, bool clamped) {
  if (options.grid_orientation != GridOrientation::kBody || clamped)
    return Eigen::Matrix3d::Identity();
  const geometry::GridAlignment alignment = geometry::AlignGridToSurface(rest_mesh);
  const bool flat_faces = alignment.score >= SimulationOptions::kMinAlignedScore;
  const bool gains =
      alignment.score > alignment.identity_score + SimulationOptions::kMinAlignmentGain;
  return flat_faces && gains ? alignment.mesh_from_grid : Eigen::Matrix3d::Identity();
}

Simulator::Simulator(const geometry::TriangleMesh& rest_mesh, const PhysicalParameters& parameters,
                     const SimulationOptions& options,
                     const std::optional<Eigen::AlignedBox3d>& fixed_region)
    : world_parameters_(parameters), options_(options) {
  ThrowIfError(parameters.Validate());
  ThrowIfError(options.Validate());
  SOFTID_THROW_UNLESS(!rest_mesh.triangles.empty(), "rest mesh has no triangles");
  pose_centre_ = rest_mesh.Bounds().center();
  mesh_from_grid_ = ChooseGridAxes(rest_mesh, options, fixed_region.has_value());
  const geometry::TriangleMesh grid_mesh = TurnedIntoGrid(rest_mesh);
  length_ = grid_mesh.Bounds().sizes().maxCoeff();
  SOFTID_THROW_UNLESS(length_ > 0.0, "rest mesh has zero extent");
  rest_frame_ = RestFrame(parameters.initial_pose, pose_centre_, mesh_from_grid_);
  parameters_ = rest_frame_.ToRest(parameters);

  BuildGrid(grid_mesh, fixed_region);
  EmbedSurface(grid_mesh);
  team_ = std::make_unique<ThreadTeam>(AssemblyThreads());
  PartitionElements();
  AssignSurfacePointsToChunks();
  const int n = mesh_.NumNodes();
  fixed_.assign(n, 0);
  if (fixed_region) {
    // The nodes on the clamp's face (ClampFacePlanes) belong to it despite rounding.
    const double tolerance = 1e-9 * mesh_.CellSize();
    const Eigen::AlignedBox3d held(fixed_region->min() - Eigen::Vector3d::Constant(tolerance),
                                   fixed_region->max() + Eigen::Vector3d::Constant(tolerance));
    for (int i = 0; i < n; ++i) fixed_[i] = held.contains(mesh_.rest_positions[i]) ? 1 : 0;
  }
  assembler_ = ElementAssembler(n, mesh_.element_nodes);
  solver_.SetThreadTeam(team_.get());
  residual_.resize(3 * n);
  update_.resize(3 * n);
  ApplyParameters();
}

geometry::TriangleMesh Simulator::TurnedIntoGrid(const geometry::TriangleMesh& rest_mesh) const {
  geometry::TriangleMesh turned = rest_mesh;
  if (mesh_from_grid_ == Eigen::Matrix3d::Identity()) return turned;
  for (Eigen::Vector3d& x : turned.vertices)
    x = mesh_from_grid_.transpose() * (x - pose_centre_) + pose_centre_;
  return turned;
}

Eigen::Vector3d Simulator::ElementCentreInMesh(int e) const {
  return mesh_from_grid_ * (mesh_.ElementCentre(e) - pose_centre_) + pose_centre_;
}

void Simulator::BuildGrid(const geometry::TriangleMesh& rest_mesh,
                          const std::optional<Eigen::AlignedBox3d>& fixed_region) {
  geometry::SignedDistanceOptions sdf_options;
  sdf_options.cells_along_longest_side = options_.cells_along_longest_side;
  sdf_options.cell_size = options_.cell_size;
  sdf_options.padding_cells = options_.padding_cells;
  sdf_options.cut_cell_samples = options_.cut_cell_samples;
  if (fixed_region) sdf_options.node_plane = ClampFacePlanes(*fixed_region, rest_mesh.Bounds());
  Result<geometry::SignedDistanceField> sdf =
      geometry::ComputeSignedDistanceField(rest_mesh, sdf_options);
  ThrowIfError(sdf.status());
  sdf_ = std::move(sdf).value();
  mesh_ = BuildHexMesh(sdf_, options_.min_cell_volume_fraction);
  // The cut cells' lattices have shaped the elements; nothing reads them again.
  sdf_.cut_cell_phi = {};
  sdf_.cut_cell_lattice = {};
  Eigen::AlignedBox3d rest_box;
  for (const Eigen::Vector3d& x : mesh_.rest_positions) rest_box.extend(x);
  rest_extent_ = rest_box.isEmpty() ? 0.0 : rest_box.diagonal().norm();
  SOFTID_THROW_UNLESS(mesh_.NumElements() > 0, "the mesh has no inside at this grid resolution");
}

// The surface carried by the grid: the rest mesh subdivided to a fraction of a cell, embedded.
void Simulator::EmbedSurface(const geometry::TriangleMesh& rest_mesh) {
  surface_ =
      geometry::SubdivideToEdgeLength(rest_mesh, options_.surface_edge_fraction * mesh_.CellSize());
  embedding_ = EmbedPoints(mesh_, surface_.vertices);
  force_embedding_ =
      EmbedPoints(mesh_, surface_.vertices, /*clamp_to_element=*/true,
                  options_.min_force_volume_fraction, options_.max_force_clamp_cells);
  surface_areas_ = geometry::VertexAreas(surface_);
}

int Simulator::AssemblyThreads() const {
  const int available = options_.threads > 0
                            ? options_.threads
                            : static_cast<int>(std::thread::hardware_concurrency());
  return std::clamp(std::min(available, mesh_.NumElements() / kMinElementsPerThread), 1,
                    kMaxSimulationThreads);
}

// Element ranges of the parallel assembly, one per team member: a node touched by two ranges is
// shared, and the elements with a shared node run on one thread.
void Simulator::PartitionElements() {
  const int threads = team_->size();
  const size_t num_elements = mesh_.element_nodes.size();
  if (threads == 1) {
    element_chunks_.assign(1, std::vector<int>(num_elements));
    std::iota(element_chunks_[0].begin(), element_chunks_[0].end(), 0);
    shared_elements_.clear();
    return;
  }
  // Ranges of equal element counts, cut across the axis where the cuts cross the fewest
  // elements: torus-drop at 3,100 cells shares 13 % of its elements when cut in index order (z
  // planes through the whole ring), fewer across x or y.
  std::vector<int> order(num_elements);
  size_t fewest_shared = num_elements + 1;
  for (int axis = -1; axis < 3; ++axis) {
    std::iota(order.begin(), order.end(), 0);
    if (axis >= 0) {
      std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
        return mesh_.ElementCentre(a)[axis] < mesh_.ElementCentre(b)[axis];
      });
    }
    std::vector<int> candidate(num_elements);
    for (size_t rank = 0; rank < num_elements; ++rank)
      candidate[order[rank]] = static_cast<int>(rank * threads / num_elements);
    const auto [chunks, shared] = SplitElements(mesh_, candidate, threads);
    if (shared.size() < fewest_shared) {
      fewest_shared = shared.size();
      element_chunks_ = chunks;
      shared_elements_ = shared;
    }
  }
}

// Each surface point's forces go with its element's range, or to the shared ones.
void Simulator::AssignSurfacePointsToChunks() {
  const int threads = team_->size();
  std::vector<int> chunk_of(mesh_.element_nodes.size(), -1);
  for (int t = 0; t < threads; ++t)
    for (int e : element_chunks_[t]) chunk_of[e] = t;
  point_chunks_.assign(threads, {});
  shared_points_.clear();
  for (int p = 0; p < force_embedding_.NumPoints(); ++p) {
    const int chunk = chunk_of[force_embedding_.element[p]];
    (chunk >= 0 ? point_chunks_[chunk] : shared_points_).push_back(p);
  }
}

void Simulator::SetParameters(const PhysicalParameters& parameters) {
  ThrowIfError(parameters.Validate());
  world_parameters_ = parameters;
  rest_frame_ = RestFrame(parameters.initial_pose, pose_centre_, mesh_from_grid_);
  parameters_ = rest_frame_.ToRest(parameters);
  ApplyParameters();
}

void Simulator::ApplyParameters() {
  BuildMassAndStiffness();
  SetUpSurfaceForces();
  Reset();
  FactorizeReference();
}

void Simulator::BuildMassAndStiffness() {
  const PhysicalParameters& parameters = parameters_;
  const double h = mesh_.CellSize();
  mass_ = Eigen::VectorXd::Zero(mesh_.NumNodes());
  stiffness_matrices_.clear();
  element_stiffness_index_.resize(mesh_.NumElements());
  std::map<std::array<double, 9>, int> distinct;  // (weights, scale) -> matrix, exact match
  element_rotation_.assign(mesh_.NumElements(), Eigen::Matrix3d::Identity());
  element_stiffness_weights_.resize(mesh_.NumElements());
  element_scale_.resize(mesh_.NumElements());
  // d K / d mu depends on the Poisson ratio for the incompatible-modes element: rebuilt on demand.
  if (options_.element != ElementFormulation::kTrilinear) {
    shear_matrices_.clear();
    element_shear_index_.clear();
  }
  const double lambda = parameters.LameLambda();
  const double mu = parameters.LameMu();
  for (int e = 0; e < mesh_.NumElements(); ++e) {
    AddLumpedMass(e);
    const double scale = parameters.stiffness_field.Scale(ElementCentreInMesh(e));
    // Ghost stiffness (as in CutFEM): nearly empty octants keep a small floor of stiffness, so
    // nodes that only touch slivers of material are not free to be pushed around by contact.
    std::array<double, 8> stiffness_weights = mesh_.element_weights[e].octant_volume;
    const double floor = options_.ghost_stiffness_fraction * h * h * h / 8.0;
    for (double& weight : stiffness_weights) weight = std::max(weight, floor);
    std::array<double, 9> key;
    std::copy(stiffness_weights.begin(), stiffness_weights.end(), key.begin());
    key[8] = scale;
    const auto [it, added] = distinct.emplace(key, static_cast<int>(stiffness_matrices_.size()));
    if (added) {
      stiffness_matrices_.push_back(
          ElementStiffness(stiffness_weights, h, scale * lambda, scale * mu, options_.element));
    }
    element_stiffness_index_[e] = it->second;
    element_stiffness_weights_[e] = stiffness_weights;
    element_scale_[e] = scale;
  }
}

// Lumped mass: each corner gets the material of its own octant (the row sum of the consistent
// mass matrix under the same octant quadrature as the stiffness). A uniform V_e / 8 share would
// put the material of a cut cell on its empty corners as well, moving mass outwards: torus-drop
// fitted at 16 cells on a 28-cell capture then gives E 7.9 % high (octant lumping on an octant
// capture: 0.9 %). A floor of a quarter of the uniform share keeps nodes touching only slivers
// from being nearly massless; the element's mass is unchanged.
void Simulator::AddLumpedMass(int e) {
  const auto& w = mesh_.element_weights[e];
  std::array<double, 8> share;
  double total = 0.0;
  for (int c = 0; c < 8; ++c) {
    share[c] = std::max(w.octant_volume[c], kMinNodeMassShare * w.volume / 8.0);
    total += share[c];
  }
  for (int c = 0; c < 8; ++c)
    mass_[mesh_.element_nodes[e][c]] += parameters_.density * w.volume * share[c] / total;
}

void Simulator::SetUpSurfaceForces() {
  const PhysicalParameters& parameters = parameters_;
  contact_ = ContactLaw();
  if (parameters.ground) {
    contact_.plane = *parameters.ground;
    contact_.stiffness = parameters.contact_stiffness > 0.0
                             ? parameters.contact_stiffness
                             : DefaultContactStiffness(parameters.youngs_modulus, length_);
    contact_.smoothing =
        options_.contact_smoothing > 0.0 ? options_.contact_smoothing : 1e-3 * length_;
    contact_.damping = parameters.contact_damping;
    contact_.friction_coefficient = parameters.friction_coefficient;
    contact_.friction_velocity_scale = options_.friction_velocity_scale;
  }
  has_surface_forces_ = parameters.ground.has_value() || parameters.drag_linear > 0.0 ||
                        parameters.drag_quadratic > 0.0;
}

// Reference factor: the step matrix at rest (no rotation, no contact).
void Simulator::FactorizeReference() {
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(3 * mesh_.NumNodes());
  const bool saved_forces = has_surface_forces_;
  has_surface_forces_ = false;
  Assemble(Mode::kDynamic, zero, zero, zero);
  has_surface_forces_ = saved_forces;
  // The solver keeps its symbolic analysis: only the numbers change with the parameters.
  factor_history_.clear();
  factor_history_bytes_ = 0;
  ThrowIfError(solver_.Factorize(assembler_.matrix(), Eigen::Matrix3d::Identity(),
                                 LinearSolver::Symmetry::kSymmetric));
}

int Simulator::num_fixed_nodes() const {
  return static_cast<int>(std::count(fixed_.begin(), fixed_.end(), 1));
}

void Simulator::SetState(const SimulationState& state) {
  SOFTID_THROW_UNLESS(state.u.size() == 3 * mesh_.NumNodes() && state.v.size() == state.u.size() &&
                          state.a.size() == state.u.size(),
                      "state size does not match the mesh");
  state_ = state;
  estimate_first_ = false;
}

void Simulator::Reset() {
  const int n = mesh_.NumNodes();
  state_.time = 0.0;
  state_.u = Eigen::VectorXd::Zero(3 * n);
  state_.v = Eigen::VectorXd::Zero(3 * n);
  Eigen::Vector3d com = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) com += mass_[i] * mesh_.rest_positions[i];
  com /= mass_.sum();
  for (int i = 0; i < n; ++i) {
    if (fixed_[i]) continue;
    state_.v.segment<3>(3 * i) =
        parameters_.initial_velocity +
        parameters_.initial_angular_velocity.cross(mesh_.rest_positions[i] - com);
  }
  state_.a = InitialAcceleration(state_.v);
  estimate_first_ = false;
}

Eigen::VectorXd Simulator::InitialAcceleration(const Eigen::VectorXd& v) {
  // M a0 = f(u0, v0): Assemble with a = 0 gives r = D v0 + g(u0) - f_ext, so a0 = -M^-1 r.
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(v.size());
  UpdateLaggedNormalForces();
  Assemble(Mode::kDynamic, state_.u, v, zero, /*residual_only=*/true);
  Eigen::VectorXd a(v.size());
  for (int i = 0; i < mesh_.NumNodes(); ++i) {
    a.segment<3>(3 * i) = fixed_[i] ? Eigen::Vector3d::Zero().eval()
                                    : Eigen::Vector3d(-residual_.segment<3>(3 * i) / mass_[i]);
  }
  return a;
}

void Simulator::NewmarkKinematics(const Eigen::VectorXd& u, Eigen::VectorXd* v,
                                  Eigen::VectorXd* a) const {
  const double dt = options_.time_step;
  const double beta = options_.newmark_beta;
  const double gamma = options_.newmark_gamma;
  // a_{n+1} = (u_{n+1} - u_n - dt v_n - dt^2 (1/2 - beta) a_n) / (beta dt^2)
  // v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})
  a->noalias() =
      (u - state_.u - dt * state_.v - (dt * dt * (0.5 - beta)) * state_.a) / (beta * dt * dt);
  v->noalias() = state_.v + dt * ((1.0 - gamma) * state_.a + gamma * (*a));
}

LinearSolver::Symmetry Simulator::TangentSymmetry(Mode mode) const {
  // Newton's dynamic tangent leaves out the (non-symmetric) geometric term, and every other block
  // is symmetric up to round-off (element blocks R K R^T, contact and drag blocks w_i w_j J with J
  // symmetric); only the primal-dual friction tangent is not.
  return newton_tangent_ && mode == Mode::kDynamic && !use_friction_iterate_
             ? LinearSolver::Symmetry::kSymmetric
             : LinearSolver::Symmetry::kGeneral;
}

// One NewtonSolve: the settings fixed for the solve, and the state its stages share: the iterate
// (the simulator's u_next_, v_next_, a_next_ with the work vectors residual_, rhs_, update_), the
// body rotation and residual norm of the last assembly, and the summary.
struct Simulator::NewtonRun {
  NewtonRun(Simulator& simulator, Mode mode);
  // The friction iterate and the tangent recording serve this solve only.
  ~NewtonRun() {
    sim.use_friction_iterate_ = false;
    sim.record_tangent_ = false;
  }
  NewtonRun(const NewtonRun&) = delete;
  NewtonRun& operator=(const NewtonRun&) = delete;

  void TakeOverFactor();
  void Predict();
  void BeginIterating();
  enum class Start { kIterate, kConverged, kDiverged };
  Start FirstAssembly();
  Eigen::Matrix3d AssembleAtIterate(bool residual_only, bool reuse_rotations);
  const LinearSolver::Matrix& StepMatrix();
  LinearSolver::Summary SolveStep();
  LinearSolver::Summary SolveCorrected(const std::vector<int>& nodes,
                                       const LinearSolver::Summary& plain);
  bool SolveForUpdate();
  void TakeUpdate(int iteration, double full_step, bool small);
  double EstimateUpdate();
  void TakeEstimate(double estimate);
  StepSummary Finish();
  StepSummary Diverged() {
    summary.diverged = true;
    return summary;
  }
  bool ResidualFinite() const { return std::isfinite(residual_norm); }

  Simulator& sim;
  const Mode mode;
  const bool dynamic;
  // Newton's matrix is the residual's Jacobian divided by 1 - alpha_f (see AssembleStep).
  const double matrix_scale;
  // Matrix-free: GMRES applies the step matrix by elements (StepTangentOperator) from what every
  // assembly of this step records; a matrix is assembled only to be factorised.
  const bool matrix_free;
  // The friction force estimate starts from the law at v_n: a sticking point keeps its force.
  const bool friction_active;
  double tolerance = 0.0;  // on the max norm of an update [m]
  LinearSolver::Options linear;
  StepSummary summary;
  Eigen::Matrix3d body_rotation;
  double residual_norm = 0.0;
  // Once a solve of this step outgrew the plain factor, the rest use the contact correction.
  bool contact_correction = false;
};

Simulator::NewtonRun::NewtonRun(Simulator& simulator, Mode mode)
    : sim(simulator),
      mode(mode),
      dynamic(mode == Mode::kDynamic),
      matrix_scale(dynamic ? 1.0 - sim.options_.generalized_alpha_f : 1.0),
      matrix_free(dynamic && sim.newton_tangent_ && sim.options_.matrix_free_newton),
      friction_active(dynamic && sim.parameters_.ground &&
                      sim.parameters_.friction_coefficient > 0.0 && sim.has_surface_forces_) {
  const SimulationOptions& options = sim.options_;
  linear.relative_tolerance = options.linear_tolerance;
  linear.max_iterations = options.max_linear_iterations;
  // Under friction the velocities must be solved well inside the friction law's knee too: a
  // velocity error comparable to friction_velocity_scale changes the friction force by a large
  // fraction of mu f_n and accumulates over a slide (see kFrictionVelocityTolerance).
  // (Friction acts where the contact force at the step's start is positive: lagged friction.)
  tolerance = options.newton_tolerance * sim.mesh_.CellSize();
  if (friction_active &&
      std::any_of(sim.lagged_normal_force_.begin(), sim.lagged_normal_force_.end(),
                  [](double f) { return f > 0.0; })) {
    const double dv_du = options.newmark_gamma / (options.newmark_beta * options.time_step);
    tolerance =
        std::min(tolerance, kFrictionVelocityTolerance * options.friction_velocity_scale / dv_du);
  }
}

// A factor renewed in the background takes over at the start of a step, at the same point
// whatever the timing: once the solves since have done about its work, at the latest at the
// kMaxFactorizationSteps-th step.
void Simulator::NewtonRun::TakeOverFactor() {
  if (dynamic)
    sim.solver_.FinishFactorizeWhenDue(kMaxFactorizationSteps);
  else
    sim.solver_.FinishFactorize();
  if (dynamic) sim.RecordFactor();
}

// The iterate's start: a dynamic step predicts a_{n+1} = a_n, a static solve starts at rest.
void Simulator::NewtonRun::Predict() {
  const SimulationState& state = sim.state_;
  const double dt = sim.options_.time_step;
  sim.u_next_ = state.u;
  sim.v_next_ = state.v;
  sim.a_next_ = state.a;
  if (dynamic) {
    sim.u_next_ = state.u + dt * state.v + (0.5 * dt * dt) * state.a;
    for (int i = 0; i < sim.mesh_.NumNodes(); ++i) {
      if (sim.fixed_[i]) sim.u_next_.segment<3>(3 * i).setZero();
    }
    sim.NewmarkKinematics(sim.u_next_, &sim.v_next_, &sim.a_next_);
  } else {
    sim.v_next_.setZero();
    sim.a_next_.setZero();
  }
}

// Turns on what this solve's assemblies keep for it (the friction iterate, the recorded tangent).
void Simulator::NewtonRun::BeginIterating() {
  sim.use_friction_iterate_ = friction_active && sim.options_.primal_dual_friction;
  if (sim.use_friction_iterate_) {
    const int num_points = sim.force_embedding_.NumPoints();
    sim.friction_iterate_.resize(num_points);
    for (int p = 0; p < num_points; ++p) {
      sim.friction_iterate_[p] =
          FrictionForce(sim.contact_, sim.force_embedding_.Interpolate(sim.mesh_, sim.state_.v, p),
                        sim.lagged_normal_force_[p]);
    }
  }
  sim.record_tangent_ = matrix_free;
  sim.update_.setZero();
  residual_norm = 0.0;
}

// The residual and Newton's matrix at the iterate (the residual alone when residual_only).
Eigen::Matrix3d Simulator::NewtonRun::AssembleAtIterate(bool residual_only, bool reuse_rotations) {
  if (!residual_only) ++summary.tangent_assemblies;
  if (matrix_free && !residual_only) {
    // A tangent where the last assembly was (reuse_rotations) is already recorded.
    if (reuse_rotations) return body_rotation;
    residual_only = true;
  }
  if (dynamic)
    return sim.AssembleStep(sim.u_next_, sim.v_next_, sim.a_next_, residual_only, reuse_rotations);
  return sim.Assemble(mode, sim.u_next_, sim.v_next_, sim.a_next_, residual_only, reuse_rotations);
}

// Newton's matrix at the iterate, where the last assembly was, for a factorisation.
const LinearSolver::Matrix& Simulator::NewtonRun::StepMatrix() {
  if (matrix_free)
    sim.AssembleStep(sim.u_next_, sim.v_next_, sim.a_next_, /*residual_only=*/false, true);
  return sim.assembler_.matrix();
}

// GMRES on Newton's system for update_ (its initial guess on entry). With nodes in contact: on the
// plain factor first, then, once that takes more than kPlainIterationsBeforeCorrection
// iterations, with the contact correction from where it stopped (a restart of GMRES, which is
// why a solve without contact is never cut short).
LinearSolver::Summary Simulator::NewtonRun::SolveStep() {
  if (!matrix_free)
    return sim.solver_.Solve(sim.assembler_.matrix(), sim.rhs_, body_rotation, linear,
                             &sim.update_);
  sim.step_tangent_.Bind(sim.TangentViews());
  const std::vector<int>& contact_nodes = sim.ContactNodes();
  LinearSolver::Summary plain;
  if (!contact_correction || contact_nodes.empty()) {
    LinearSolver::Options first = linear;
    if (!contact_nodes.empty())
      first.max_iterations = std::min(linear.max_iterations, kPlainIterationsBeforeCorrection);
    plain = sim.solver_.Solve(sim.step_tangent_, sim.rhs_, body_rotation, first, &sim.update_);
    if (plain.converged || first.max_iterations == linear.max_iterations) return plain;
    contact_correction = true;
  }
  return SolveCorrected(contact_nodes, plain);
}

// The rest of a solve (`plain`: what the plain factor did) with the correction on `nodes`.
LinearSolver::Summary Simulator::NewtonRun::SolveCorrected(const std::vector<int>& nodes,
                                                           const LinearSolver::Summary& plain) {
  sim.solver_.SetCorrection(nodes, sim.step_tangent_.NodeRows(nodes));
  LinearSolver::Options rest = linear;
  rest.max_iterations = std::max(0, linear.max_iterations - plain.iterations);
  LinearSolver::Summary solve =
      sim.solver_.Solve(sim.step_tangent_, sim.rhs_, body_rotation, rest, &sim.update_);
  sim.solver_.ClearCorrection();
  solve.iterations += plain.iterations;
  return solve;
}

// The first assembly of the step. After a step that converged with one Newton update (free
// flight, gentle contact) the predictor is nearly right and the rotated factor nearly the step
// matrix, so the preconditioner's estimate may already be converged
// (SimulationOptions::newton_estimate_first); otherwise it is GMRES's initial guess.
Simulator::NewtonRun::Start Simulator::NewtonRun::FirstAssembly() {
  if (dynamic && sim.estimate_first_) {
    const double estimate = EstimateUpdate();
    if (!ResidualFinite()) return Start::kDiverged;
    if (estimate <= tolerance) {
      TakeEstimate(estimate);
      summary.newton_iterations = 1;
      return Start::kConverged;
    }
    if (!std::isfinite(estimate)) sim.update_.setZero();
    body_rotation = AssembleAtIterate(/*residual_only=*/false, /*reuse_rotations=*/true);
  } else {
    body_rotation = AssembleAtIterate(/*residual_only=*/false, /*reuse_rotations=*/false);
    residual_norm = sim.residual_.norm();
  }
  return Start::kIterate;
}

// Newton's update into update_ from the last assembly. False when none could be had (no static
// factor, or GMRES failed even with a fresh one).
bool Simulator::NewtonRun::SolveForUpdate() {
  LinearSolver& solver = sim.solver_;
  if (!dynamic && !solver.HasFactor()) {
    if (!solver.Factorize(sim.assembler_.matrix(), body_rotation).ok()) return false;
  }
  sim.rhs_ = (-1.0 / matrix_scale) * sim.residual_;
  LinearSolver::Summary solve = SolveStep();
  summary.linear_iterations += solve.iterations;
  if (dynamic && solve.converged && solver.RefactorPays() && !solver.FactorizationPending()) {
    // The reference factor no longer fits (large deformation, contact): renew it, in the
    // background on a team; the steps go on with the old one until the new one is due.
    summary.refactorized =
        solver.StartFactorize(StepMatrix(), body_rotation, sim.TangentSymmetry(mode)).ok();
  } else if (!solve.converged) {
    // Needed now. When that fails the previous factor stays in use.
    summary.refactorized =
        solver.Factorize(StepMatrix(), body_rotation, sim.TangentSymmetry(mode)).ok();
    if (dynamic) sim.RecordFactor();
    sim.update_.setZero();
    solve = SolveStep();
    summary.linear_iterations += solve.iterations;
    if (!solve.converged && !(solve.relative_residual < 1e-6)) return false;
  }
  return true;
}

// Moves the iterate along update_: all of it when small (converged), else as far as the contact
// and friction step limits let it (the line search that stands in for a merit function).
void Simulator::NewtonRun::TakeUpdate(int iteration, double full_step, bool small) {
  const double friction_limit =
      dynamic && !sim.use_friction_iterate_ ? sim.FrictionStepLimit(sim.v_next_, sim.update_) : 1.0;
  const double step =
      small ? 1.0 : std::min(sim.ContactStepLimit(sim.u_next_, sim.update_), friction_limit);
  if (sim.use_friction_iterate_) sim.v_before_ = sim.v_next_;
  sim.u_next_ += step * sim.update_;
  if (dynamic) sim.NewmarkKinematics(sim.u_next_, &sim.v_next_, &sim.a_next_);
  if (sim.use_friction_iterate_) sim.AdvanceFrictionIterate(sim.v_before_, sim.v_next_);
  summary.newton_iterations = iteration + 1;
  summary.max_update = step * full_step;
}

// The residual alone at the iterate and the preconditioner's estimate of the next update from it,
// P^-1 (-r), into update_ (one pair of triangular solves instead of a tangent and GMRES): returns
// its max norm, NaN when the residual is not finite.
double Simulator::NewtonRun::EstimateUpdate() {
  body_rotation = AssembleAtIterate(/*residual_only=*/true, /*reuse_rotations=*/false);
  residual_norm = sim.residual_.norm();
  if (!std::isfinite(residual_norm)) return std::numeric_limits<double>::quiet_NaN();
  sim.rhs_ = (-1.0 / matrix_scale) * sim.residual_;
  sim.solver_.Precondition(sim.rhs_, body_rotation, &sim.update_);
  ++summary.linear_iterations;
  return sim.update_.lpNorm<Eigen::Infinity>();
}

// A small estimate is taken as the last update: the step has converged.
void Simulator::NewtonRun::TakeEstimate(double estimate) {
  sim.u_next_ += sim.update_;
  if (dynamic) sim.NewmarkKinematics(sim.u_next_, &sim.v_next_, &sim.a_next_);
  summary.max_update = estimate;
  summary.converged = true;
}

// The iterate becomes the state, unless the body has stretched past belief.
StepSummary Simulator::NewtonRun::Finish() {
  if (sim.ExceedsExtent(sim.u_next_)) return Diverged();
  sim.state_.u = sim.u_next_;
  sim.state_.v = sim.v_next_;
  sim.state_.a = sim.a_next_;
  sim.estimate_first_ = sim.options_.newton_estimate_first && dynamic && summary.converged &&
                        summary.newton_iterations == 1;
  return summary;
}

// Newton on the step equations with the consistent tangent, less the terms AssembleElement leaves
// out of Newton's tangent. Full steps, except that no surface point may be pushed deeper into the
// ground than a few contact smoothing lengths beyond where the contact was linearised (a
// continuous-collision filter, as in IPC), nor have its slip reversed by more than a few friction
// velocity scales: from outside either smooth knee the linearisation sees no stiffness and would
// overshoot far across it.
// The residual norm is no merit function here: in bending, element forces exceed the net nodal
// forces a thousandfold and ||r|| grows over good steps.
//
// Convergence: the update falls below newton_tolerance * h. After a large update the next one is
// first estimated by the preconditioner alone, P^-1 (-r), from the residual (no tangent assembly,
// one pair of triangular solves instead of a GMRES solve): when that estimate is already small it
// is taken as the last update and the step ends. Otherwise it is GMRES's initial guess, so the
// estimate is not wasted. In free flight this saves a full Newton iteration per step.
StepSummary Simulator::NewtonSolve(Mode mode) {
  NewtonRun newton(*this, mode);
  newton.TakeOverFactor();
  newton.Predict();
  newton.BeginIterating();
  switch (newton.FirstAssembly()) {
    case NewtonRun::Start::kDiverged: return newton.Diverged();
    case NewtonRun::Start::kConverged: return newton.Finish();
    case NewtonRun::Start::kIterate: break;
  }
  for (int it = 0; it < options_.max_newton_iterations; ++it) {
    if (!newton.ResidualFinite() || !newton.SolveForUpdate()) return newton.Diverged();
    const double full_step = update_.lpNorm<Eigen::Infinity>();
    if (!std::isfinite(full_step)) return newton.Diverged();
    const bool small = full_step <= newton.tolerance;
    newton.TakeUpdate(it, full_step, small);
    // A converged update needs no new assembly: the state is final.
    if (small) {
      newton.summary.converged = true;
      break;
    }
    const double estimate = newton.EstimateUpdate();
    if (!newton.ResidualFinite()) break;
    if (estimate <= newton.tolerance) {
      newton.TakeEstimate(estimate);
      break;
    }
    if (it + 1 < options_.max_newton_iterations) {
      newton.body_rotation =
          newton.AssembleAtIterate(/*residual_only=*/false, /*reuse_rotations=*/true);
    }
  }
  if (!newton.ResidualFinite()) return newton.Diverged();
  return newton.Finish();
}

const std::vector<int>& Simulator::ContactNodes() {
  contact_nodes_.clear();
  if (!options_.contact_correction) return contact_nodes_;
  // A point whose Jacobian is below a tenth of its interpolated inertia c_m m_p barely changes the
  // step matrix: what the reference factor misses there, GMRES corrects in an iteration or two.
  constexpr double kRelevantShare = 0.1;
  std::vector<char>& member = contact_member_;
  member.assign(mesh_.NumNodes(), 0);
  for (int p = 0; p < static_cast<int>(point_active_.size()); ++p) {
    if (!point_active_[p]) continue;
    const auto& nodes = mesh_.element_nodes[force_embedding_.element[p]];
    const auto& w = force_embedding_.weights[p];
    double point_mass = 0.0;
    for (int k = 0; k < 8; ++k) point_mass += w[k] * mass_[nodes[k]];
    const double inertia = tangent_mass_coefficient_ * point_mass;
    if (point_jacobians_[p].norm() < kRelevantShare * inertia) continue;
    for (int node : nodes) member[node] = 1;
  }
  for (int i = 0; i < mesh_.NumNodes(); ++i)
    if (member[i] && !fixed_[i]) contact_nodes_.push_back(i);
  return contact_nodes_;
}

StepTangentOperator::Views Simulator::TangentViews() {
  StepTangentOperator::Views views;
  views.element_nodes = &mesh_.element_nodes;
  views.stiffness_matrices = &stiffness_matrices_;
  views.stiffness_index = &element_stiffness_index_;
  views.rotations = &element_rotation_;
  views.stiffness_coefficient = tangent_stiffness_coefficient_;
  views.mass = &mass_;
  views.mass_coefficient = tangent_mass_coefficient_;
  views.fixed = &fixed_;
  views.points = &force_embedding_;
  views.point_jacobians = &point_jacobians_;
  views.point_active = &point_active_;
  views.element_chunks = &element_chunks_;
  views.shared_elements = &shared_elements_;
  views.point_chunks = &point_chunks_;
  views.shared_points = &shared_points_;
  views.team = team_.get();
  views.assembled_nonzeros = static_cast<double>(assembler_.matrix().nonZeros());
  return views;
}

bool Simulator::ExceedsExtent(const Eigen::VectorXd& u) const {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (size_t i = 0; i < mesh_.rest_positions.size(); ++i) {
    const Eigen::Vector3d x = mesh_.rest_positions[i] + u.segment<3>(3 * i);
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  return !((hi - lo).norm() <= options_.max_extent_ratio * rest_extent_);
}

namespace {
// Memory the factor history of one simulation may hold: ~11 factors at 3,100 cells (11 MB each),
// 2-3 at 10k cells; the forward passes of a fit renew the factor a few times per second simulated.
constexpr size_t kFactorHistoryBytes = size_t{128} << 20;
}  // namespace

void Simulator::RecordFactor() {
  backward_factor_time_ = std::numeric_limits<double>::quiet_NaN();
  if (!options_.adjoint_reuses_forward_factors) return;
  std::shared_ptr<LinearSolver::FactorSnapshot> factor = solver_.CurrentFactor();
  if (factor == nullptr) return;
  // Entries from this step on belong to an earlier run that went further (times are a whole
  // number of steps apart).
  const double time = state_.time;
  while (!factor_history_.empty() &&
         factor_history_.back().time > time - 0.5 * options_.time_step) {
    if (factor_history_.back().factor != nullptr)
      factor_history_bytes_ -= LinearSolver::FactorBytes(*factor_history_.back().factor);
    factor_history_.pop_back();
  }
  if (!factor_history_.empty() && factor_history_.back().factor == factor) return;
  const size_t bytes = LinearSolver::FactorBytes(*factor);
  const bool kept = factor_history_bytes_ + bytes <= kFactorHistoryBytes;
  if (kept) factor_history_bytes_ += bytes;
  factor_history_.push_back({time, kept ? std::move(factor) : nullptr});
}

void Simulator::UseForwardFactor(double step_start_time) {
  // The last entry at or before the step's start (times are a whole number of steps apart).
  const auto after = std::upper_bound(
      factor_history_.begin(), factor_history_.end(), step_start_time + 0.5 * options_.time_step,
      [](double time, const FactorUse& use) { return time < use.time; });
  if (after == factor_history_.begin()) return;
  const FactorUse& use = *std::prev(after);
  // Switch once per entry: a factor the adjoint renewed itself in between stays until the next.
  if (use.time == backward_factor_time_) return;
  backward_factor_time_ = use.time;
  solver_.UseFactor(use.factor);
}

void Simulator::EvaluateStepResidual(const Eigen::VectorXd& u_next, Eigen::VectorXd* residual,
                                     Eigen::SparseMatrix<double>* jacobian) {
  SOFTID_THROW_UNLESS(u_next.size() == state_.u.size(), "u_next size does not match the mesh");
  UpdateLaggedNormalForces();
  Eigen::VectorXd v(u_next.size()), a(u_next.size());
  NewmarkKinematics(u_next, &v, &a);
  newton_tangent_ = false;
  AssembleStep(u_next, v, a);
  newton_tangent_ = true;
  if (residual) *residual = residual_;
  if (jacobian) *jacobian = (1.0 - options_.generalized_alpha_f) * assembler_.matrix();
}

void Simulator::AdvanceFrictionIterate(const Eigen::VectorXd& v, const Eigen::VectorXd& v_new) {
  // lambda' = lambda + dlambda with lambda s + mu f_n v_t = 0 linearised at (v, lambda):
  // dlambda = -(rho + (mu f_n T + lambda v_t^T / s) dv) / s, rho = lambda s + mu f_n v_t; then
  // projected onto the tangent plane and into the cone |lambda| <= mu f_n.
  const Eigen::Vector3d& n = contact_.plane.normal;
  const double eps = contact_.friction_velocity_scale;
  for (int p = 0; p < force_embedding_.NumPoints(); ++p) {
    const double limit = parameters_.friction_coefficient * lagged_normal_force_[p];
    if (!(limit > 0.0)) {
      friction_iterate_[p].setZero();
      continue;
    }
    Eigen::Vector3d vt = force_embedding_.Interpolate(mesh_, v, p);
    vt -= n.dot(vt) * n;
    Eigen::Vector3d dvt = force_embedding_.Interpolate(mesh_, v_new, p) - vt;
    dvt -= n.dot(dvt) * n;
    const double s = std::sqrt(vt.squaredNorm() + eps * eps);
    Eigen::Vector3d lambda = friction_iterate_[p] - n.dot(friction_iterate_[p]) * n;
    lambda = -(limit / s) * (vt + dvt) - lambda * (vt.dot(dvt) / (s * s));
    lambda -= n.dot(lambda) * n;
    const double norm = lambda.norm();
    if (norm > limit) lambda *= limit / norm;
    friction_iterate_[p] = lambda;
  }
}

void Simulator::UpdateLaggedNormalForces() {
  lagged_normal_force_.assign(force_embedding_.NumPoints(), 0.0);
  if (!parameters_.ground || parameters_.friction_coefficient <= 0.0) return;
  for (int p = 0; p < force_embedding_.NumPoints(); ++p) {
    const Eigen::Vector3d xp =
        force_embedding_.rest_positions[p] + force_embedding_.Interpolate(mesh_, state_.u, p);
    lagged_normal_force_[p] = ContactNormalForce(contact_, surface_areas_[p], xp);
  }
}

double Simulator::ContactStepLimit(const Eigen::VectorXd& u, const Eigen::VectorXd& update) const {
  if (!parameters_.ground) return 1.0;
  constexpr double kMaxPenetrationStep = 4.0;  // contact smoothing lengths
  constexpr double kMinStep = 1.0 / 64.0;
  const double allowed = kMaxPenetrationStep * contact_.smoothing;
  double step = 1.0;
  for (int p = 0; p < force_embedding_.NumPoints(); ++p) {
    const Eigen::Vector3d move = force_embedding_.Interpolate(mesh_, update, p);
    const double change = contact_.plane.normal.dot(move);
    if (change >= 0.0) continue;
    const double d = contact_.plane.SignedDistance(force_embedding_.rest_positions[p] +
                                                   force_embedding_.Interpolate(mesh_, u, p));
    const double floor = std::min(d, 0.0) - allowed;
    if (d + change < floor) step = std::min(step, (floor - d) / change);
  }
  return std::max(step, kMinStep);
}

double Simulator::FrictionStepLimit(const Eigen::VectorXd& v, const Eigen::VectorXd& update) const {
  if (!parameters_.ground || parameters_.friction_coefficient <= 0.0) return 1.0;
  constexpr double kMaxReversal = 4.0;  // friction velocity scales past zero slip
  constexpr double kMinStep = 1.0 / 64.0;
  const double eps = contact_.friction_velocity_scale;
  const double dv_du = options_.newmark_gamma / (options_.newmark_beta * options_.time_step);
  const Eigen::Vector3d& n = contact_.plane.normal;
  double step = 1.0;
  for (int p = 0; p < force_embedding_.NumPoints(); ++p) {
    if (lagged_normal_force_[p] <= 0.0) continue;
    Eigen::Vector3d vt = force_embedding_.Interpolate(mesh_, v, p);
    vt -= n.dot(vt) * n;
    const double speed = vt.norm();
    if (speed <= eps) continue;  // inside the knee the linearisation is good
    Eigen::Vector3d dvt = dv_du * force_embedding_.Interpolate(mesh_, update, p);
    dvt -= n.dot(dvt) * n;
    const double along = -dvt.dot(vt) / speed;  // how far the step slows the slip
    const double allowed = speed + kMaxReversal * eps;
    if (along > allowed) step = std::min(step, allowed / along);
  }
  return std::max(step, kMinStep);
}

StepSummary Simulator::Step() {
  UpdateLaggedNormalForces();
  const StepSummary summary = NewtonSolve(Mode::kDynamic);
  if (!summary.diverged) state_.time += options_.time_step;
  return summary;
}

StepSummary Simulator::SolveStatic() {
  // The static Jacobian differs from the dynamic one: factorise it separately, then restore.
  LinearSolver dynamic_solver = std::move(solver_);
  solver_ = LinearSolver();
  solver_.SetThreadTeam(team_.get());
  const StepSummary summary = NewtonSolve(Mode::kStatic);
  solver_ = std::move(dynamic_solver);
  return summary;
}

std::vector<Eigen::Vector3d> Simulator::SurfacePositions() const {
  std::vector<Eigen::Vector3d> positions(embedding_.NumPoints());
  const Eigen::Isometry3d& X_WS = rest_frame_.world_from_rest();
  for (int p = 0; p < embedding_.NumPoints(); ++p) {
    positions[p] =
        X_WS * (embedding_.rest_positions[p] + embedding_.Interpolate(mesh_, state_.u, p));
  }
  return positions;
}

geometry::TriangleMesh Simulator::DeformedSurface() const {
  geometry::TriangleMesh mesh = surface_;
  mesh.vertices = SurfacePositions();
  return mesh;
}

Energies Simulator::ComputeEnergies() const {
  Energies energies;
  const double h = mesh_.CellSize();
  for (int i = 0; i < mesh_.NumNodes(); ++i) {
    const Eigen::Vector3d x = mesh_.rest_positions[i] + state_.u.segment<3>(3 * i);
    energies.kinetic += 0.5 * mass_[i] * state_.v.segment<3>(3 * i).squaredNorm();
    energies.gravitational -=
        mass_[i] * world_parameters_.gravity.dot(rest_frame_.world_from_rest() * x);
  }
  std::array<Eigen::Vector3d, 8> x;
  for (int e = 0; e < mesh_.NumElements(); ++e) {
    const auto& nodes = mesh_.element_nodes[e];
    Vector24d rest, displaced;
    for (int c = 0; c < 8; ++c) {
      x[c] = mesh_.rest_positions[nodes[c]] + state_.u.segment<3>(3 * nodes[c]);
      rest.segment<3>(3 * c) = mesh_.rest_positions[nodes[c]];
      displaced.segment<3>(3 * c) = x[c];
    }
    const Eigen::Matrix3d r = PolarRotation(DeformationGradient(x, h));
    const Vector24d local = RotateCorners(r.transpose(), displaced) - rest;
    energies.elastic += 0.5 * local.dot(StiffnessOf(e) * local);
  }
  return energies;
}

Eigen::Vector3d Simulator::CentreOfMass() const {
  Eigen::Vector3d com = Eigen::Vector3d::Zero();
  for (int i = 0; i < mesh_.NumNodes(); ++i) {
    com += mass_[i] * (mesh_.rest_positions[i] + state_.u.segment<3>(3 * i));
  }
  return rest_frame_.world_from_rest() * (com / mass_.sum());
}

Eigen::Vector3d Simulator::CentreOfMassVelocity() const {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int i = 0; i < mesh_.NumNodes(); ++i) p += mass_[i] * state_.v.segment<3>(3 * i);
  return rest_frame_.world_from_rest().linear() * (p / mass_.sum());
}

}  // namespace softid::fem
