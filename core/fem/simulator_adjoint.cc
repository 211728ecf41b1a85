// The discrete adjoint of Simulator::Step and Simulator::Reset (Weiss et al. 2020, Sec. 4.3), with
// the derivatives of the step residual with respect to every physical parameter.
//
// Step n -> n+1 solves r(u', V(u', s), A(u', s); u, p) = 0 for u', where s = (u, v, a) is the
// state at step n, V and A are the Newmark velocity and acceleration, and u enters r also through
// the lagged friction normal force. With J = dr/du' (exact, total), the adjoint of u' is
//   J^T lambda = u'_bar + (dV/du') v'_bar + (dA/du') a'_bar,
// the parameters receive -lambda^T dr/dp, and the state s receives its explicit share through V,
// A and the lagged force. See core/doc/notation.md for the symbols.
#include <array>
#include <cmath>
#include <map>

#include "core/common/check.h"
#include "core/fem/corotation.h"
#include "core/fem/hex_element.h"
#include "core/fem/point_force_derivatives.h"
#include "core/fem/simulator.h"

namespace softid::fem {

void Simulator::BuildShearStiffness() {
  if (!element_shear_index_.empty()) return;
  const double h = mesh_.CellSize();
  element_shear_index_.resize(mesh_.NumElements());
  std::map<std::array<double, 8>, int> distinct;  // weights -> matrix, exact match
  for (int e = 0; e < mesh_.NumElements(); ++e) {
    const auto [it, added] =
        distinct.emplace(element_stiffness_weights_[e], static_cast<int>(shear_matrices_.size()));
    if (added)
      shear_matrices_.push_back(ElementShearDerivative(element_stiffness_weights_[e], h,
                                                       parameters_.LameLambda(),
                                                       parameters_.LameMu(), options_.element));
    element_shear_index_[e] = it->second;
  }
}

namespace {

// Lame parameters and their derivatives with respect to the Poisson ratio.
struct LameDerivatives {
  double lambda = 0.0, mu = 0.0;
  double dlambda_dnu = 0.0, dmu_dnu = 0.0;
};

LameDerivatives LameDerivativesOf(const PhysicalParameters& p) {
  const double nu = p.poisson_ratio;
  LameDerivatives lame;
  lame.lambda = p.LameLambda();
  lame.mu = p.LameMu();
  lame.dmu_dnu = -p.youngs_modulus / (2.0 * (1.0 + nu) * (1.0 + nu));
  lame.dlambda_dnu = p.youngs_modulus * (1.0 + 2.0 * nu * nu) /
                     ((1.0 + nu) * (1.0 + nu) * (1.0 - 2.0 * nu) * (1.0 - 2.0 * nu));
  return lame;
}

// One team member's share of the parameter gradient through the elements, and through the
// surface points: each member sums its own, and the shares are added in member order, so the sum
// does not depend on the timing.
struct ElementShare {
  double youngs_modulus = 0.0, poisson_ratio = 0.0, stiffness_damping = 0.0;
  std::vector<double> stiffness_field;
};
struct SurfaceShare {
  Eigen::Vector3d ground_normal = Eigen::Vector3d::Zero();
  double ground_offset = 0.0, stiffness = 0.0, contact_damping = 0.0, friction_coefficient = 0.0;
  double drag_linear = 0.0, drag_quadratic = 0.0;
};

}  // namespace

// One ResidualAdjoint: its inputs and outputs, which its stages (elements, nodes, surface points)
// share.
struct Simulator::ResidualAdjointPass {
  // Where the surface forces are evaluated, and where their velocity adjoint goes.
  struct SurfaceInputs {
    const Eigen::VectorXd& u;
    const Eigen::VectorXd& v;
    Eigen::VectorXd* velocity_adjoint;
    double dv_du = 0.0;
    bool drag = false;
  };

  void AddElements() const;
  void AddElement(int e, const LameDerivatives& lame, ElementShare* share) const;
  void AddNodes() const;
  void AddSurfacePoints() const;
  void AddSurfacePoint(int pt, const SurfaceInputs& in, SurfaceShare* share) const;
  void ClearFixedNodes() const;

  const Simulator& sim;
  const PhysicalParameters& p;
  const double h;  // cell size [m]
  const Eigen::VectorXd& u;
  const Eigen::VectorXd& v;
  const Eigen::VectorXd& a;
  const Eigen::VectorXd& u_previous;
  const Eigen::VectorXd& lambda;
  const bool rotations_current;
  Eigen::VectorXd* velocity_adjoint;
  Eigen::VectorXd* previous_adjoint;
  ParameterGradient* gradient;
  SurfaceAdjoint* surface;
};

// Elements: r_e = R K_e l, l = R^T (x + beta_k v) - X, K_e = s (lambda K_lambda + mu K_mu).
// Each range of the assembly's partition runs on its own member (an element writes the velocity
// adjoint of its own nodes only), the shared elements afterwards.
void Simulator::ResidualAdjointPass::AddElements() const {
  const LameDerivatives lame = LameDerivativesOf(p);
  const StiffnessField& field = p.stiffness_field;
  if (field.kind == StiffnessField::Kind::kRegions)
    gradient->stiffness_field.resize(field.regions.size(), 0.0);
  if (field.kind == StiffnessField::Kind::kLinear) gradient->stiffness_field.resize(3, 0.0);
  std::vector<ElementShare> shares(sim.element_chunks_.size() + 1);
  for (ElementShare& share : shares)
    share.stiffness_field.assign(gradient->stiffness_field.size(), 0.0);
  sim.team_->Run([&](int member) {
    for (int e : sim.element_chunks_[member]) AddElement(e, lame, &shares[member]);
  });
  for (int e : sim.shared_elements_) AddElement(e, lame, &shares.back());
  for (const ElementShare& share : shares) {
    gradient->youngs_modulus += share.youngs_modulus;
    gradient->poisson_ratio += share.poisson_ratio;
    gradient->stiffness_damping += share.stiffness_damping;
    for (size_t i = 0; i < share.stiffness_field.size(); ++i)
      gradient->stiffness_field[i] += share.stiffness_field[i];
  }
}

void Simulator::ResidualAdjointPass::AddElement(int e, const LameDerivatives& lame,
                                                ElementShare* share) const {
  const HexMesh& mesh = sim.mesh_;
  const double beta_k = p.stiffness_damping;
  const StiffnessField& field = p.stiffness_field;
  const auto& nodes = mesh.element_nodes[e];
  std::array<Eigen::Vector3d, 8> x;
  Vector24d lambda_local, v_local, l;
  for (int c = 0; c < 8; ++c) {
    x[c] = mesh.rest_positions[nodes[c]] + u.segment<3>(3 * nodes[c]);
    lambda_local.segment<3>(3 * c) = lambda.segment<3>(3 * nodes[c]);
  }
  if (lambda_local.isZero(0.0)) return;
  const Eigen::Matrix3d r =
      rotations_current ? sim.element_rotation_[e] : PolarRotation(DeformationGradient(x, h));
  const Eigen::Matrix3d rt = r.transpose();
  Vector24d rotated_lambda;  // R^T lambda_e
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d vc = v.segment<3>(3 * nodes[c]);
    v_local.segment<3>(3 * c).noalias() = rt * vc;
    l.segment<3>(3 * c).noalias() = rt * (x[c] + beta_k * vc) - mesh.rest_positions[nodes[c]];
    rotated_lambda.segment<3>(3 * c).noalias() = rt * lambda_local.segment<3>(3 * c);
  }
  const Matrix24d& k = sim.StiffnessOf(e);
  const Vector24d sigma = k * l;
  // lambda^T r_e = (R^T lambda)^T K l.
  const double work = rotated_lambda.dot(sigma);
  share->youngs_modulus -= work / p.youngs_modulus;
  // d K / d nu l = (dlambda/lambda) K l + s (dmu - mu dlambda/lambda) K_mu l.
  const double scale = sim.element_scale_[e];
  const Vector24d shear = sim.ShearStiffnessOf(e) * l;
  share->poisson_ratio -=
      (lame.dlambda_dnu / lame.lambda) * work +
      scale * (lame.dmu_dnu - lame.mu * lame.dlambda_dnu / lame.lambda) * rotated_lambda.dot(shear);
  // d r_e / d beta_k = R K R^T v.
  const Vector24d k_rotated_lambda = k * rotated_lambda;
  share->stiffness_damping -= k_rotated_lambda.dot(v_local);
  // Velocity: d r_e / d v = beta_k R K R^T.
  if (beta_k != 0.0) {
    for (int c = 0; c < 8; ++c) {
      velocity_adjoint->segment<3>(3 * nodes[c]).noalias() +=
          beta_k * (r * k_rotated_lambda.segment<3>(3 * c));
    }
  }
  // Stiffness field: r_e is proportional to the element's scale s.
  if (field.kind == StiffnessField::Kind::kRegions) {
    const Eigen::Vector3d centre = sim.ElementCentreInMesh(e);
    int region = -1;
    for (size_t i = 0; i < field.regions.size(); ++i) {
      if (field.regions[i].box.contains(centre)) region = static_cast<int>(i);
    }
    if (region >= 0) share->stiffness_field[region] -= work / scale;
  } else if (field.kind == StiffnessField::Kind::kLinear) {
    const Eigen::Vector3d offset = sim.ElementCentreInMesh(e) - field.origin;
    for (int i = 0; i < 3; ++i) share->stiffness_field[i] -= work * offset[i];
  }
}

// Nodes: inertia, mass damping, gravity; r_i = m_i (a_i + alpha v_i - g).
void Simulator::ResidualAdjointPass::AddNodes() const {
  const Eigen::VectorXd& mass = sim.mass_;
  for (int i = 0; i < sim.mesh_.NumNodes(); ++i) {
    if (sim.fixed_[i]) continue;
    const Eigen::Vector3d li = lambda.segment<3>(3 * i);
    const Eigen::Vector3d vi = v.segment<3>(3 * i);
    const Eigen::Vector3d inertial = a.segment<3>(3 * i) + p.mass_damping * vi - p.gravity;
    gradient->density -= mass[i] / p.density * li.dot(inertial);
    gradient->mass_damping -= mass[i] * li.dot(vi);
    gradient->gravity += mass[i] * li;
    velocity_adjoint->segment<3>(3 * i) += p.mass_damping * mass[i] * li;
  }
}

// Surface points: r_i -= w_i f_p, so -lambda^T dr/dq = lambda_p . df_p/dq with
// lambda_p = sum_i w_i lambda_i. A point writes to its element's nodes only, so the points run on
// the team like the forward assembly's (each range's own, then the shared ones).
void Simulator::ResidualAdjointPass::AddSurfacePoints() const {
  const int n = sim.mesh_.NumNodes();
  const SimulationOptions& options = sim.options_;
  SurfaceInputs in{
      .u = surface != nullptr && surface->u != nullptr ? *surface->u : u,
      .v = surface != nullptr && surface->v != nullptr ? *surface->v : v,
      .velocity_adjoint = velocity_adjoint,
      .dv_du = options.newmark_gamma / (options.newmark_beta * options.time_step),
  };
  if (surface != nullptr) {
    surface->velocity_adjoint.setZero(3 * n);
    surface->jacobian_adjoint.setZero(3 * n);
    in.velocity_adjoint = &surface->velocity_adjoint;
  }
  in.drag = p.drag_linear > 0.0 || p.drag_quadratic > 0.0;
  std::vector<SurfaceShare> shares(sim.point_chunks_.size() + 1);
  sim.team_->Run([&](int member) {
    for (int pt : sim.point_chunks_[member]) AddSurfacePoint(pt, in, &shares[member]);
  });
  for (int pt : sim.shared_points_) AddSurfacePoint(pt, in, &shares.back());
  double d_stiffness = 0.0;
  for (const SurfaceShare& share : shares) {
    gradient->ground_normal += share.ground_normal;
    gradient->ground_offset += share.ground_offset;
    d_stiffness += share.stiffness;
    gradient->contact_damping += share.contact_damping;
    gradient->friction_coefficient += share.friction_coefficient;
    gradient->drag_linear += share.drag_linear;
    gradient->drag_quadratic += share.drag_quadratic;
  }
  gradient->contact_stiffness += d_stiffness;
  // The default k = DefaultContactStiffness(E, L) is linear in E.
  if (p.ground && p.contact_stiffness <= 0.0)
    gradient->youngs_modulus += d_stiffness * kDefaultContactStiffnessFactor / sim.length_;
}

void Simulator::ResidualAdjointPass::AddSurfacePoint(int pt, const SurfaceInputs& in,
                                                     SurfaceShare* share) const {
  const HexMesh& mesh = sim.mesh_;
  const SurfaceEmbedding& embedding = sim.force_embedding_;
  const Eigen::Vector3d lambda_p = embedding.Interpolate(mesh, lambda, pt);
  if (lambda_p.isZero(0.0)) return;
  const Eigen::Vector3d vp = embedding.Interpolate(mesh, in.v, pt);
  const double area = sim.surface_areas_[pt];
  // Drag f = -(A/4) (c1 + c2 |v|) v; its derivatives exist at c = 0 too (for screening).
  const double projected = 0.25 * area;
  const double speed = vp.norm();
  share->drag_linear -= projected * vp.dot(lambda_p);
  share->drag_quadratic -= projected * speed * vp.dot(lambda_p);
  const auto& nodes = mesh.element_nodes[embedding.element[pt]];
  const auto& w = embedding.weights[pt];
  Eigen::Vector3d velocity_part = Eigen::Vector3d::Zero();  // (df/dv)^T lambda_p
  bool ground_force = false;
  Eigen::Vector3d xp = Eigen::Vector3d::Zero();
  if (p.ground) {
    xp = embedding.rest_positions[pt] + embedding.Interpolate(mesh, in.u, pt);
    const Eigen::Vector3d xp_previous =
        embedding.rest_positions[pt] + embedding.Interpolate(mesh, u_previous, pt);
    ground_force = !GroundContactDerivativesVanish(sim.contact_, xp, xp_previous);
    if (ground_force) {
      const GroundForceDerivatives d =
          GroundContactForceDerivatives(sim.contact_, area, xp, vp, xp_previous);
      share->ground_normal += d.d_normal.transpose() * lambda_p;
      share->ground_offset += d.d_offset.dot(lambda_p);
      share->stiffness += d.d_stiffness.dot(lambda_p);
      share->contact_damping += d.d_damping.dot(lambda_p);
      share->friction_coefficient += d.d_friction.dot(lambda_p);
      velocity_part += d.d_velocity.transpose() * lambda_p;
      const Eigen::Vector3d previous_part = d.d_previous_position.transpose() * lambda_p;
      for (int c = 0; c < 8; ++c)
        previous_adjoint->segment<3>(3 * nodes[c]) += w[c] * previous_part;
    }
  }
  // Far from the ground without drag the point exerts no force: nothing else to add.
  if (!ground_force && !in.drag) return;
  const PointForce drag_force = AirDragForce(p.drag_linear, p.drag_quadratic, area, vp);
  velocity_part -= drag_force.damping.transpose() * lambda_p;
  // -(dr/dv)^T lambda = (df/dv)^T lambda_p, spread back to the nodes.
  for (int c = 0; c < 8; ++c) in.velocity_adjoint->segment<3>(3 * nodes[c]) -= w[c] * velocity_part;
  if (surface != nullptr) {
    // The point's block of the step matrix, as Assemble builds it (exact tangent).
    Eigen::Matrix3d jacobian = drag_force.StepJacobian(in.dv_du);
    if (ground_force) {
      jacobian += GroundContactForce(sim.contact_, area, xp, vp, sim.lagged_normal_force_[pt])
                      .StepJacobian(in.dv_du);
    }
    const Eigen::Vector3d product = jacobian.transpose() * lambda_p;
    for (int c = 0; c < 8; ++c)
      surface->jacobian_adjoint.segment<3>(3 * nodes[c]) += w[c] * product;
  }
}

// A clamped node has no equation and no state of its own to receive an adjoint.
void Simulator::ResidualAdjointPass::ClearFixedNodes() const {
  for (int i = 0; i < sim.mesh_.NumNodes(); ++i) {
    if (!sim.fixed_[i]) continue;
    velocity_adjoint->segment<3>(3 * i).setZero();
    previous_adjoint->segment<3>(3 * i).setZero();
    if (surface != nullptr) surface->velocity_adjoint.segment<3>(3 * i).setZero();
  }
}

void Simulator::ResidualAdjoint(const Eigen::VectorXd& u, const Eigen::VectorXd& v,
                                const Eigen::VectorXd& a, const Eigen::VectorXd& u_previous,
                                const Eigen::VectorXd& lambda, Eigen::VectorXd* velocity_adjoint,
                                Eigen::VectorXd* previous_adjoint, ParameterGradient* gradient,
                                bool rotations_current, SurfaceAdjoint* surface) {
  BuildShearStiffness();
  const int n = mesh_.NumNodes();
  velocity_adjoint->setZero(3 * n);
  previous_adjoint->setZero(3 * n);
  const ResidualAdjointPass pass{.sim = *this,
                                 .p = parameters_,
                                 .h = mesh_.CellSize(),
                                 .u = u,
                                 .v = v,
                                 .a = a,
                                 .u_previous = u_previous,
                                 .lambda = lambda,
                                 .rotations_current = rotations_current,
                                 .velocity_adjoint = velocity_adjoint,
                                 .previous_adjoint = previous_adjoint,
                                 .gradient = gradient,
                                 .surface = surface};
  pass.AddElements();
  pass.AddNodes();
  pass.AddSurfacePoints();
  pass.ClearFixedNodes();
}

// One step of the backward pass: the adjoint of the step's end state (u', V(u'), A(u')) through
// the step's residual, back to its start state, with the parameters' share into the gradient.
struct Simulator::AdjointStep {
  AdjointStep(Simulator& sim, const SimulationState& previous, const SimulationState& next,
              StateAdjoint* adjoint, ParameterGradient* gradient)
      : sim(sim),
        previous(previous),
        next(next),
        adjoint(adjoint),
        gradient(gradient),
        dt(sim.options_.time_step),
        beta(sim.options_.newmark_beta),
        gamma(sim.options_.newmark_gamma),
        da_du(1.0 / (beta * dt * dt)),
        dv_du(gamma / (beta * dt)),
        alpha_m(sim.options_.generalized_alpha_m),
        alpha_f(sim.options_.generalized_alpha_f),
        n(sim.mesh_.NumNodes()) {}

  // Adjoint of u' through u', V(u') and A(u'), zero at fixed nodes.
  Eigen::VectorXd RightHandSide() const {
    Eigen::VectorXd rhs = adjoint->u + dv_du * adjoint->v + da_du * adjoint->a;
    for (int i = 0; i < n; ++i) {
      if (sim.fixed_[i]) rhs.segment<3>(3 * i).setZero();
    }
    return rhs;
  }

  // The exact Jacobian at the end of the step, assembled; the preconditioner's factor chosen.
  void AssembleExactJacobian() {
    // A factor the adjoint renewed during the previous (later) step takes over here, unless the
    // forward pass solved this step with another (see factor_history_). One the forward pass left
    // pending at its end is dropped when the forward's own factors take over: computing or
    // waiting for it would be for nothing.
    if (!sim.backward_factorization_pending_ && sim.options_.adjoint_reuses_forward_factors)
      sim.solver_.DiscardFactorize();
    else
      sim.solver_.FinishFactorize();
    sim.backward_factorization_pending_ = false;
    sim.UseForwardFactor(previous.time);
    sim.SetState(previous);
    sim.UpdateLaggedNormalForces();
    sim.newton_tangent_ = false;
    // The contact points' Jacobians, to find the nodes of the preconditioner's contact correction.
    sim.record_tangent_ = sim.options_.contact_correction;
    rotation = sim.AssembleStep(next.u, next.v, next.a);
    sim.record_tangent_ = false;
    sim.newton_tangent_ = true;
  }

  // The preconditioner's correction on the contact nodes (subdomain_correction.h) for this step's
  // transposed solve: one setup per step, beside the 10-40 iterations an adjoint solve to its
  // tighter tolerance takes in contact.
  void CorrectOnContactNodes() {
    const std::vector<int>& nodes = sim.ContactNodes();
    if (nodes.empty()) return;
    sim.solver_.SetCorrection(
        nodes, SubdomainCorrection::Rows(sim.assembler_.matrix(), nodes, /*transposed=*/true));
  }

  // lambda from J^T lambda = rhs (the assembled matrix is J / (1 - alpha_f), see AssembleStep: the
  // solve gives (1 - alpha_f) lambda), from the previous step's lambda as the first guess.
  Status SolveForLambda(const Eigen::VectorXd& rhs) {
    lambda = Eigen::VectorXd::Zero(3 * n);
    if (rhs.isZero(0.0)) return Status::Ok();
    if (sim.adjoint_guess_.size() == lambda.size()) lambda = sim.adjoint_guess_;
    LinearSolver::Options linear;
    linear.relative_tolerance = sim.options_.adjoint_linear_tolerance;
    linear.max_iterations = sim.options_.max_linear_iterations;
    LinearSolver& solver = sim.solver_;
    const LinearSolver::Matrix& jacobian = sim.assembler_.matrix();
    constexpr auto kTransposed = LinearSolver::Operator::kTransposed;
    CorrectOnContactNodes();
    LinearSolver::Summary solve =
        solver.Solve(jacobian, rhs, rotation, linear, &lambda, kTransposed);
    solver.ClearCorrection();
    sim.backward_linear_iterations_ += solve.iterations;
    if (!solve.converged) {
      if (solver.Factorize(jacobian, rotation).ok()) {
        lambda.setZero();
        solve = solver.Solve(jacobian, rhs, rotation, linear, &lambda, kTransposed);
        sim.backward_linear_iterations_ += solve.iterations;
      }
      // GMRES can stagnate on the exact tangent (indefinite and non-symmetric where strong
      // friction sticks); a direct LU solves it.
      if (!solve.converged)
        solve = LinearSolver::SolveDirect(jacobian, rhs, linear, &lambda, kTransposed);
      if (!solve.converged) {
        return Status::Internal("adjoint solve at t = " + std::to_string(next.time) +
                                " s did not converge (relative residual " +
                                std::to_string(solve.relative_residual) + ")");
      }
    }
    // The same ski-rental rule as the forward pass: renew the factor once the extra iterations
    // of a stale one have cost more than a factorisation.
    if (solver.RefactorPays() && !solver.FactorizationPending())
      sim.backward_factorization_pending_ = solver.StartFactorize(jacobian, rotation).ok();
    return Status::Ok();
  }

  // The residual's adjoint at the step's evaluation point, and the adjoint of the start state.
  void PropagateToStart() {
    const bool generalized_alpha = sim.UsesGeneralizedAlpha();
    // (d r_b / d u_f)^T lambda of the body forces (elastic, damping, inertia) from the matrix
    // J' = dr_b/du_f + dv_du dr_b/dv_f + c M + S / (1 - alpha_f) (c: Assemble's inertia
    // coefficient, S the surface forces' blocks at the end of the step), less all but the first.
    Eigen::VectorXd position_adjoint;
    if (generalized_alpha) {
      lambda /= 1.0 - alpha_f;
      position_adjoint = sim.assembler_.matrix().transpose() * lambda;
    }
    // The body forces hold at the evaluation point (u_f, v_f, a_m) of AssembleStep, the surface
    // forces at the end of the step.
    Eigen::VectorXd velocity_adjoint, previous_adjoint;
    SurfaceAdjoint surface{&next.u, &next.v, {}, {}};
    sim.ResidualAdjoint(*sim.step_u_, *sim.step_v_, *sim.step_a_, previous.u, lambda,
                        &velocity_adjoint, &previous_adjoint, gradient,
                        /*rotations_current=*/true, generalized_alpha ? &surface : nullptr);
    ThroughNewmark(velocity_adjoint, previous_adjoint, generalized_alpha ? &surface : nullptr);
    if (generalized_alpha) ThroughEvaluationPoint(velocity_adjoint, surface, &position_adjoint);
  }

  // Explicit dependence of V and A on the previous state, with the residual's share
  // (dr/dv)^T lambda = (1 - alpha_f) (dr_b/dv_f)^T lambda + (dr_s/dv)^T lambda and
  // (dr/da)^T lambda = (1 - alpha_m) M lambda subtracted.
  void ThroughNewmark(const Eigen::VectorXd& velocity_adjoint,
                      const Eigen::VectorXd& previous_adjoint, const SurfaceAdjoint* surface) {
    Eigen::VectorXd v_bar = adjoint->v - (1.0 - alpha_f) * velocity_adjoint;
    if (surface != nullptr) v_bar -= surface->velocity_adjoint;
    Eigen::VectorXd a_bar = adjoint->a;
    for (int i = 0; i < n; ++i)
      a_bar.segment<3>(3 * i) -= (1.0 - alpha_m) * sim.mass_[i] * lambda.segment<3>(3 * i);
    const Eigen::VectorXd w = a_bar + (gamma * dt) * v_bar;  // adjoint flowing into A
    adjoint->u = previous_adjoint - da_du * w;
    adjoint->v = v_bar - (dt * da_du) * w;
    adjoint->a = (dt * (1.0 - gamma)) * v_bar - ((0.5 - beta) / beta) * w;
  }

  // Generalized-alpha: the evaluation point's own dependence on the previous state, u_f and v_f
  // through alpha_f, a_m through alpha_m.
  void ThroughEvaluationPoint(const Eigen::VectorXd& velocity_adjoint,
                              const SurfaceAdjoint& surface, Eigen::VectorXd* position_adjoint) {
    const double inertia = (1.0 - alpha_m) / (1.0 - alpha_f) * da_du;
    *position_adjoint -= dv_du * velocity_adjoint + surface.jacobian_adjoint / (1.0 - alpha_f);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d m_lambda = sim.mass_[i] * lambda.segment<3>(3 * i);
      position_adjoint->segment<3>(3 * i) -= inertia * m_lambda;
      adjoint->a.segment<3>(3 * i) -= alpha_m * m_lambda;
    }
    adjoint->u -= alpha_f * *position_adjoint;
    adjoint->v -= alpha_f * velocity_adjoint;
  }

  void ClearFixedNodes() {
    for (int i = 0; i < n; ++i) {
      if (!sim.fixed_[i]) continue;
      adjoint->u.segment<3>(3 * i).setZero();
      adjoint->v.segment<3>(3 * i).setZero();
      adjoint->a.segment<3>(3 * i).setZero();
    }
  }

  Simulator& sim;
  const SimulationState& previous;
  const SimulationState& next;
  StateAdjoint* adjoint;
  ParameterGradient* gradient;
  // Newmark's step and parameters, dV/du' and dA/du', generalized-alpha's weights.
  const double dt, beta, gamma, da_du, dv_du, alpha_m, alpha_f;
  const int n;               // nodes
  Eigen::Matrix3d rotation;  // of the body at the step's end (AssembleStep)
  Eigen::VectorXd lambda;    // the step residual's adjoint
};

Status Simulator::BackpropagateStep(const SimulationState& previous, const SimulationState& next,
                                    StateAdjoint* adjoint, ParameterGradient* gradient) {
  const int n = mesh_.NumNodes();
  SOFTID_DEMAND(adjoint->u.size() == 3 * n && adjoint->v.size() == 3 * n &&
                adjoint->a.size() == 3 * n);
  AdjointStep step(*this, previous, next, adjoint, gradient);
  const Eigen::VectorXd rhs = step.RightHandSide();
  step.AssembleExactJacobian();
  SOFTID_RETURN_IF_ERROR(step.SolveForLambda(rhs));
  adjoint_guess_ = step.lambda;
  step.PropagateToStart();
  step.ClearFixedNodes();
  return Status::Ok();
}

void Simulator::BackpropagateInitialState(const SimulationState& initial,
                                          const StateAdjoint& adjoint,
                                          ParameterGradient* gradient) {
  const int n = mesh_.NumNodes();
  adjoint_guess_.resize(0);  // the backward pass ends here
  // a0 = -M^-1 r(0, v0, 0) at free nodes. With zeta = M^-1 a0_bar, d L = -zeta^T (dr + dM a0):
  // the residual's adjoint evaluated at a = a0 supplies both terms.
  Eigen::VectorXd zeta = Eigen::VectorXd::Zero(3 * n);
  for (int i = 0; i < n; ++i) {
    if (!fixed_[i]) zeta.segment<3>(3 * i) = adjoint.a.segment<3>(3 * i) / mass_[i];
  }
  SetState(initial);
  Eigen::VectorXd velocity_adjoint, previous_adjoint;
  ResidualAdjoint(initial.u, initial.v, initial.a, initial.u, zeta, &velocity_adjoint,
                  &previous_adjoint, gradient);
  const Eigen::VectorXd v_bar = adjoint.v - velocity_adjoint;

  // v0_i = v_lin + omega x (X_i - com); the centre of mass does not depend on the density.
  Eigen::Vector3d com = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) com += mass_[i] * mesh_.rest_positions[i];
  com /= mass_.sum();
  for (int i = 0; i < n; ++i) {
    if (fixed_[i]) continue;
    const Eigen::Vector3d vi = v_bar.segment<3>(3 * i);
    gradient->initial_velocity += vi;
    gradient->initial_angular_velocity += (mesh_.rest_positions[i] - com).cross(vi);
  }
  rest_frame_.ChainToWorld(world_parameters_, gradient);
}

}  // namespace softid::fem
