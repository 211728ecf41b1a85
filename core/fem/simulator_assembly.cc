// Simulator: assembly of the step equations' residual and tangent (elements, inertia and gravity,
// surface forces, clamped nodes), and the generalized-alpha evaluation point of a dynamic step.
#include <Eigen/Cholesky>
#include <array>
#include <cmath>

#include "core/fem/corotation.h"
#include "core/fem/simulator.h"

namespace softid::fem {

Simulator::AssemblyTerms Simulator::MakeAssemblyTerms(Mode mode, bool residual_only,
                                                      bool reuse_rotations) const {
  const bool dynamic = mode == Mode::kDynamic;
  const double dt = options_.time_step;
  const double beta = options_.newmark_beta;
  const double gamma = options_.newmark_gamma;
  const double alpha_m = parameters_.mass_damping;
  const double beta_k = parameters_.stiffness_damping;
  // d a / d u and d v / d u of the Newmark update; under generalized-alpha the matrix is
  // (dr/du) / (1 - alpha_f), so the inertia's share is (1 - alpha_m) / (1 - alpha_f) of it.
  const double inertia_weight =
      (1.0 - options_.generalized_alpha_m) / (1.0 - options_.generalized_alpha_f);
  const double da_du = dynamic ? inertia_weight / (beta * dt * dt) : 0.0;
  const double dv_du = dynamic ? gamma / (beta * dt) : 0.0;
  AssemblyTerms terms;
  terms.dynamic = dynamic;
  terms.stiffness_damping = beta_k;
  terms.stiffness_coefficient = 1.0 + beta_k * dv_du;
  terms.mass_coefficient = da_du + alpha_m * dv_du;
  terms.dv_du = dv_du;
  terms.jacobian = !residual_only;
  terms.reuse_rotations = reuse_rotations;
  terms.record_tangent = record_tangent_;
  return terms;
}

Eigen::Matrix3d Simulator::Assemble(Mode mode, const Eigen::VectorXd& u, const Eigen::VectorXd& v,
                                    const Eigen::VectorXd& a, bool residual_only,
                                    bool reuse_rotations) {
  const AssemblyTerms terms = MakeAssemblyTerms(mode, residual_only, reuse_rotations);
  BeginAssembly(terms);
  const Eigen::Matrix3d rotation_sum = AssembleElements(terms, u, v);
  AssembleInertiaAndGravity(terms, v, a);
  if (has_surface_forces_) AssembleSurfaceForces(terms, u, v);
  EliminateFixedNodes(terms);
  return PolarRotation(rotation_sum);
}

void Simulator::BeginAssembly(const AssemblyTerms& terms) {
  if (terms.record_tangent) {
    tangent_stiffness_coefficient_ = terms.stiffness_coefficient;
    tangent_mass_coefficient_ = terms.mass_coefficient;
    point_jacobians_.resize(force_embedding_.NumPoints());
    point_active_.assign(force_embedding_.NumPoints(), 0);
  }
  if (terms.jacobian) {
    team_->Run([&](int member) { assembler_.SetZero(member, team_->size()); });
  }
  residual_.setZero();
}

Eigen::Matrix3d Simulator::AssembleElements(const AssemblyTerms& terms, const Eigen::VectorXd& u,
                                            const Eigen::VectorXd& v) {
  // The ranges' own elements in parallel, then the shared ones.
  auto run = [&](const std::vector<int>& elements) {
    for (int e : elements) AssembleElement(e, terms, u, v);
  };
  team_->Run([&](int member) { run(element_chunks_[member]); });
  run(shared_elements_);
  Eigen::Matrix3d rotation_sum = Eigen::Matrix3d::Zero();
  for (int e = 0; e < mesh_.NumElements(); ++e)
    rotation_sum += mesh_.element_weights[e].volume * element_rotation_[e];
  return rotation_sum;
}

void Simulator::AssembleInertiaAndGravity(const AssemblyTerms& terms, const Eigen::VectorXd& v,
                                          const Eigen::VectorXd& a) {
  const double alpha_m = parameters_.mass_damping;
  for (int i = 0; i < mesh_.NumNodes(); ++i) {
    Eigen::Vector3d inertial = -parameters_.gravity;
    if (terms.dynamic) inertial += a.segment<3>(3 * i) + alpha_m * v.segment<3>(3 * i);
    residual_.segment<3>(3 * i) += mass_[i] * inertial;
    if (terms.dynamic && terms.jacobian)
      assembler_.AddNodeBlock(i, terms.mass_coefficient * mass_[i] * Eigen::Matrix3d::Identity());
  }
}

void Simulator::AssembleSurfaceForces(const AssemblyTerms& terms, const Eigen::VectorXd& u,
                                      const Eigen::VectorXd& v) {
  // Contact, friction, drag; a point acts on its element's nodes only, so the points of the
  // ranges' own elements run in parallel too, then those of shared elements.
  const Eigen::VectorXd& surface_u = surface_u_ != nullptr ? *surface_u_ : u;
  const Eigen::VectorXd& surface_v = surface_v_ != nullptr ? *surface_v_ : v;
  const auto run_points = [&](const std::vector<int>& points) {
    for (int p : points) AssembleSurfacePoint(p, terms, surface_u, surface_v);
  };
  team_->Run([&](int member) { run_points(point_chunks_[member]); });
  run_points(shared_points_);
}

Eigen::SparseMatrix<double> Simulator::RestStiffnessMatrix() {
  const AssemblyTerms terms = MakeAssemblyTerms(Mode::kStatic, false, false);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(state_.u.size());
  newton_tangent_ = false;  // the exact element matrices (at rest the geometric term is zero)
  BeginAssembly(terms);
  AssembleElements(terms, zero, zero);
  EliminateFixedNodes(terms);
  newton_tangent_ = true;
  return assembler_.matrix();
}

void Simulator::EliminateFixedNodes(const AssemblyTerms& terms) {
  for (int i = 0; i < mesh_.NumNodes(); ++i) {
    if (!fixed_[i]) continue;
    residual_.segment<3>(3 * i).setZero();
    if (terms.jacobian) assembler_.EliminateNode(i);
  }
}

void Simulator::AssembleSurfacePoint(int p, const AssemblyTerms& terms,
                                     const Eigen::VectorXd& surface_u,
                                     const Eigen::VectorXd& surface_v) {
  const Eigen::Vector3d xp =
      force_embedding_.rest_positions[p] + force_embedding_.Interpolate(mesh_, surface_u, p);
  const double lagged_normal_force = terms.dynamic ? lagged_normal_force_[p] : 0.0;
  const bool drag =
      terms.dynamic && (parameters_.drag_linear > 0.0 || parameters_.drag_quadratic > 0.0);
  // Most points are far from the ground: no force, nothing to assemble.
  if (!drag && (!parameters_.ground || GroundContactVanishes(contact_, xp, lagged_normal_force)))
    return;
  const Eigen::Vector3d vp = terms.dynamic ? force_embedding_.Interpolate(mesh_, surface_v, p)
                                           : Eigen::Vector3d::Zero().eval();
  PointForce f;
  if (parameters_.ground) {
    f = GroundContactForce(contact_, surface_areas_[p], xp, vp, lagged_normal_force,
                           use_friction_iterate_ ? &friction_iterate_[p] : nullptr);
  }
  if (drag) {
    const PointForce drag =
        AirDragForce(parameters_.drag_linear, parameters_.drag_quadratic, surface_areas_[p], vp);
    f.force += drag.force;
    f.damping += drag.damping;
    f.stiffness_indefinite += drag.stiffness_indefinite;
  }
  if (f.force.isZero(0.0) && f.stiffness.isZero(0.0) && f.damping.isZero(0.0)) return;
  // The exact tangent, also where the contact damper's position dependence is indefinite
  // (separating contact): leaving that out made Newton converge only linearly (x0.63 per
  // iteration) when light corner nodes rebound. GMRES does not need definiteness, and the
  // preconditioner factors the symmetric part with a shift fallback.
  const int e = force_embedding_.element[p];
  const auto& w = force_embedding_.weights[p];
  const auto& nodes = mesh_.element_nodes[e];
  if (!terms.jacobian && !terms.record_tangent) {
    for (int i = 0; i < 8; ++i) residual_.segment<3>(3 * nodes[i]) -= w[i] * f.force;
    return;
  }
  const Eigen::Matrix3d jacobian = surface_jacobian_scale_ * f.StepJacobian(terms.dv_du);
  if (terms.record_tangent) {
    point_jacobians_[p] = jacobian;
    point_active_[p] = 1;
  }
  for (int i = 0; i < 8; ++i) {
    residual_.segment<3>(3 * nodes[i]) -= w[i] * f.force;
    if (!terms.jacobian) continue;
    for (int j = 0; j < 8; ++j) assembler_.AddBlock(e, i, j, (w[i] * w[j]) * jacobian);
  }
}

// What the stages of AssembleElement share: the element's corotated state.
struct Simulator::CorotatedElement {
  Eigen::Matrix3d f;   // deformation gradient at the cell centre [-]
  Eigen::Matrix3d r;   // its polar rotation R
  Eigen::Matrix3d rt;  // R^T
  Vector24d local;     // l = R^T (x + beta v) - X [m]
  Vector24d sigma;     // K l [N]
};

void Simulator::AssembleElement(int e, const AssemblyTerms& terms, const Eigen::VectorXd& u,
                                const Eigen::VectorXd& v) {
  // Elastic and stiffness-damping forces: r_e = R K l with l = R^T (x + beta v) - X, R the polar
  // rotation of F at the cell centre. Consistent tangent (d/du, v and a following u by Newmark):
  //   c_k R K R^T + R (-[sigma_a]x + sum_b K_ab [l_b]x) W_c,   sigma = K l,
  // where W_c = (tr(S) I - S)^-1 [g_c]x R^T is dw/dx_c of the rotation's spin (dR = R [w]x,
  // F = R S); see core/fem/doc/corotation.md. The second term is not symmetric.
  CorotatedElement element;
  CorotateElement(e, terms, u, v, &element);
  const auto& nodes = mesh_.element_nodes[e];
  for (int c = 0; c < 8; ++c)
    residual_.segment<3>(3 * nodes[c]).noalias() += element.r * element.sigma.segment<3>(3 * c);
  if (!terms.jacobian) return;

  // Corotated stiffness blocks c_k R K_ij R^T; K is symmetric, so block (j, i) is the transpose
  // of block (i, j).
  const Matrix24d& k = StiffnessOf(e);
  std::array<Eigen::Matrix3d, 64> stiffness;
  for (int i = 0; i < 8; ++i) {
    for (int j = i; j < 8; ++j) {
      const Eigen::Matrix3d rk = element.r * k.block<3, 3>(3 * i, 3 * j);
      stiffness[8 * i + j].noalias() = terms.stiffness_coefficient * (rk * element.rt);
      if (j != i) stiffness[8 * j + i] = stiffness[8 * i + j].transpose();
    }
  }
  std::array<Eigen::Matrix3d, 8> w;
  std::array<Eigen::Matrix3d, 8> q;
  const bool geometric = GeometricTangentTerm(e, terms, element, stiffness, &w, &q);
  for (int i = 0; i < 8; ++i) {
    for (int j = 0; j < 8; ++j) {
      Eigen::Matrix3d& block = stiffness[8 * i + j];
      if (geometric) block.noalias() += q[i] * w[j];
      assembler_.AddBlock(e, i, j, block);
    }
  }
}

void Simulator::CorotateElement(int e, const AssemblyTerms& terms, const Eigen::VectorXd& u,
                                const Eigen::VectorXd& v, CorotatedElement* element) {
  const auto& nodes = mesh_.element_nodes[e];
  std::array<Eigen::Vector3d, 8> x;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d& p = mesh_.rest_positions[nodes[c]];
    x[c] = p + u.segment<3>(3 * nodes[c]);
  }
  element->f = DeformationGradient(x, mesh_.CellSize());
  if (!terms.reuse_rotations) element_rotation_[e] = PolarRotation(element->f);
  element->r = element_rotation_[e];
  element->rt = element->r.transpose();
  const bool damp = terms.dynamic && terms.stiffness_damping > 0.0;
  for (int c = 0; c < 8; ++c) {
    Eigen::Vector3d y = x[c];
    if (damp) y += terms.stiffness_damping * v.segment<3>(3 * nodes[c]);
    element->local.segment<3>(3 * c).noalias() = element->rt * y - mesh_.rest_positions[nodes[c]];
  }
  element->sigma.noalias() = StiffnessOf(e) * element->local;
}

bool Simulator::GeometricTangentTerm(int e, const AssemblyTerms& terms,
                                     const CorotatedElement& element,
                                     const std::array<Eigen::Matrix3d, 64>& stiffness,
                                     std::array<Eigen::Matrix3d, 8>* w,
                                     std::array<Eigen::Matrix3d, 8>* q) const {
  // Spin derivative W_c; skipped when S is degenerate (two singular values summing to zero
  // only under inversion), where the rotation is not differentiable. Newton's tangent in a
  // dynamic step leaves this geometric (rotation-derivative) term out altogether: it scales with
  // the stress while the step matrix is dominated by the mass term, so Newton takes as many
  // iterations without it (torus-drop impact: 2.03 vs 2.04 per step), and the symmetric
  // remainder suits the Cholesky preconditioner better (GMRES 8.1 vs 9.2 per step). The
  // adjoint's Jacobian and static solves (no mass term) keep it.
  const Eigen::Matrix3d s = element.rt * element.f;
  const Eigen::Matrix3d spin = s.trace() * Eigen::Matrix3d::Identity() - s;
  if (!(std::abs(spin.determinant()) > 1e-12 && !(newton_tangent_ && terms.dynamic))) return false;
  const double h = mesh_.CellSize();
  const auto& centre_gradients = CentreGradientsUnitCell();
  const Matrix24d& k = StiffnessOf(e);
  const Eigen::Matrix3d spin_inverse = spin.inverse();
  std::array<Eigen::Matrix3d, 8> skew_local;
  for (int b = 0; b < 8; ++b) skew_local[b] = Skew(element.local.segment<3>(3 * b));
  for (int c = 0; c < 8; ++c) {
    (*w)[c].noalias() = spin_inverse * (Skew(centre_gradients[c] / h) * element.rt);
    Eigen::Matrix3d z = -Skew(element.sigma.segment<3>(3 * c));
    for (int b = 0; b < 8; ++b) z.noalias() += k.block<3, 3>(3 * c, 3 * b) * skew_local[b];
    (*q)[c].noalias() = element.r * z;
  }
  // Projected Newton: a strongly compressed element's stress stiffness can outweigh its
  // inertia and make the step matrix indefinite (GMRES then stalls). Keep the exact term only
  // where the element's own block, with its share of the inertia, stays positive definite.
  // Below a few percent strain the stress stiffness is far too small to matter.
  constexpr double kCheckStrain = 0.05;
  if (!newton_tangent_ ||
      (s - Eigen::Matrix3d::Identity()).lpNorm<Eigen::Infinity>() < kCheckStrain)
    return true;
  Matrix24d symmetric;
  for (int i = 0; i < 8; ++i) {
    for (int j = 0; j < 8; ++j) {
      symmetric.block<3, 3>(3 * i, 3 * j).noalias() = stiffness[8 * i + j] + (*q)[i] * (*w)[j];
    }
  }
  symmetric = 0.5 * (symmetric + symmetric.transpose()).eval();
  symmetric.diagonal().array() +=
      terms.mass_coefficient * parameters_.density * mesh_.element_weights[e].volume / 8.0;
  return Eigen::LLT<Matrix24d>(symmetric).info() == Eigen::Success;
}

Eigen::Matrix3d Simulator::AssembleStep(const Eigen::VectorXd& u, const Eigen::VectorXd& v,
                                        const Eigen::VectorXd& a, bool residual_only,
                                        bool reuse_rotations) {
  if (!UsesGeneralizedAlpha()) {
    step_u_ = &u;
    step_v_ = &v;
    step_a_ = &a;
  } else {
    const double alpha_m = options_.generalized_alpha_m;
    const double alpha_f = options_.generalized_alpha_f;
    alpha_u_ = (1.0 - alpha_f) * u + alpha_f * state_.u;
    alpha_v_ = (1.0 - alpha_f) * v + alpha_f * state_.v;
    alpha_a_ = (1.0 - alpha_m) * a + alpha_m * state_.a;
    step_u_ = &alpha_u_;
    step_v_ = &alpha_v_;
    step_a_ = &alpha_a_;
    surface_u_ = &u;
    surface_v_ = &v;
    surface_jacobian_scale_ = 1.0 / (1.0 - alpha_f);
  }
  const Eigen::Matrix3d rotation =
      Assemble(Mode::kDynamic, *step_u_, *step_v_, *step_a_, residual_only, reuse_rotations);
  surface_u_ = nullptr;
  surface_v_ = nullptr;
  surface_jacobian_scale_ = 1.0;
  return rotation;
}
}  // namespace softid::fem
