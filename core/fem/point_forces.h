// Forces on surface points from the surroundings: penalty contact with the ground plane,
// regularised Coulomb friction, and air drag. Each returns the force and its derivatives, so the
// implicit step can put them in its Jacobian (they are symmetric positive semi-definite).
#pragma once

#include <Eigen/Core>

#include "core/fem/physical_parameters.h"

namespace softid::fem {

struct PointForce {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();      // f [N]
  Eigen::Matrix3d stiffness = Eigen::Matrix3d::Zero();  // -df/dx [N/m]
  Eigen::Matrix3d damping = Eigen::Matrix3d::Zero();    // -df/dv [N s/m]
  // The rest of -df/dx, which can be indefinite: the position dependence of the normal damping
  // (its coefficient follows the penalty's slope). Kept apart so callers see which part of the
  // tangent is not positive semi-definite; Newton and the adjoint both use the sum.
  Eigen::Matrix3d stiffness_indefinite = Eigen::Matrix3d::Zero();  // [N/m]

  // The force's block of an implicit step's matrix, -df/dx - (dv/dx) df/dv with dv/dx = dv_du
  // (the Newmark velocity's derivative): the exact tangent, indefinite part included.
  Eigen::Matrix3d StepJacobian(double dv_du) const {
    return stiffness + dv_du * damping + stiffness_indefinite;
  }
};

struct ContactLaw {
  GroundPlane plane;
  double stiffness = 0.0;                 // k [Pa/m]: pressure per metre of penetration
  double smoothing = 0.0;                 // 1/a [m]: softplus width of the onset
  double damping = 0.0;                   // c [s]: normal damping = c * (-df/dx) v
  double friction_coefficient = 0.0;      // mu [-]
  double friction_velocity_scale = 1e-3;  // eps [m/s]
};

// Normal penalty force magnitude f_n = k A softplus(-a d) / a with d = n.x - offset [N]: only
// repulsive, smooth; 0 (quickly) when the point is far above the plane.
double ContactNormalForce(const ContactLaw& law, double area, const Eigen::Vector3d& x);

// Penalty f_n n, normal damping, and friction -mu f_n_lagged v_t / sqrt(|v_t|^2 + eps^2). The
// friction uses the normal force of the previous time step (`lagged_normal_force`), so within a
// step it depends on v alone and its Jacobian is symmetric; coupling it to this step's f_n makes
// Newton stall at impacts, where f_n jumps.
//
// `friction_iterate`, when given, is Newton's current estimate lambda of the friction force (a
// primal-dual Newton, as Chan, Golub & Mulet's for total variation): the damping then holds
// (1/s)(mu f_n T + lambda v_t^T / s) with s = sqrt(|v_t|^2 + eps^2), the linearisation of
// lambda s + mu f_n v_t = 0, instead of the exact -df/dv, which it equals when lambda is the
// friction force. The exact tangent sees almost no resistance along a fast slip, so a step that
// brings a sliding point to rest overshoots into reversed slip and Newton cycles between the two
// sides; with lambda lagging the reversal, the tangent resists it. The force is always the exact
// one.
PointForce GroundContactForce(const ContactLaw& law, double area, const Eigen::Vector3d& x,
                              const Eigen::Vector3d& v, double lagged_normal_force,
                              const Eigen::Vector3d* friction_iterate = nullptr);

// Whether GroundContactForce is exactly zero at x whatever the velocity: no friction acts and the
// point is so far above the ground (40 smoothing lengths) that the softplus force is below double
// precision. Lets the assembly skip a point's velocity.
bool GroundContactVanishes(const ContactLaw& law, const Eigen::Vector3d& x,
                           double lagged_normal_force);

// The friction force -mu f_n_lagged v_t / sqrt(|v_t|^2 + eps^2) alone [N].
Eigen::Vector3d FrictionForce(const ContactLaw& law, const Eigen::Vector3d& v,
                              double lagged_normal_force);

// Drag on a point of area A: f = -(A / 4) (c1 + c2 |v|) v (projected area ~ surface / 4).
PointForce AirDragForce(double drag_linear, double drag_quadratic, double area,
                        const Eigen::Vector3d& v);

}  // namespace softid::fem
