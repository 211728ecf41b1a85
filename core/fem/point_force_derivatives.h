// Parameter derivatives of the surface point forces, for the adjoint. The forward step only needs
// d f / d x and d f / d v (PointForce); the backward pass also needs the derivatives with respect
// to the ground plane, the contact law's coefficients, and the previous step's position (through
// the lagged normal force of friction).
#pragma once

#include <Eigen/Core>

#include "core/fem/point_forces.h"

namespace softid::fem {

struct GroundForceDerivatives {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();                // f [N], as GroundContactForce
  Eigen::Matrix3d d_normal = Eigen::Matrix3d::Zero();             // d f / d n (n a free vector)
  Eigen::Vector3d d_offset = Eigen::Vector3d::Zero();             // d f / d offset
  Eigen::Vector3d d_stiffness = Eigen::Vector3d::Zero();          // d f / d k
  Eigen::Vector3d d_damping = Eigen::Vector3d::Zero();            // d f / d c
  Eigen::Vector3d d_friction = Eigen::Vector3d::Zero();           // d f / d mu
  Eigen::Matrix3d d_velocity = Eigen::Matrix3d::Zero();           // d f / d v
  Eigen::Matrix3d d_previous_position = Eigen::Matrix3d::Zero();  // d f / d x_prev
};

// Whether GroundContactForceDerivatives is all zero: the point is 40 smoothing lengths above the
// ground now and at the previous step (no force, no lagged normal force, to double precision).
bool GroundContactDerivativesVanish(const ContactLaw& law, const Eigen::Vector3d& x,
                                    const Eigen::Vector3d& x_previous);

// GroundContactForce(law, area, x, v, ContactNormalForce(law, area, x_previous)) and its
// derivatives. Friction terms are differentiated even when law.friction_coefficient is 0, so the
// gradient with respect to mu at mu = 0 is available (the diagnosis screens friction there).
GroundForceDerivatives GroundContactForceDerivatives(const ContactLaw& law, double area,
                                                     const Eigen::Vector3d& x,
                                                     const Eigen::Vector3d& v,
                                                     const Eigen::Vector3d& x_previous);

}  // namespace softid::fem
