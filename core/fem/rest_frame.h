// The initial pose (PhysicalParameters::initial_pose) as a change of frame. The simulation runs in
// the grid's frame S, where the rest mesh lies turned by R0^T about c (R0 = mesh_from_grid: the
// identity unless the grid follows the body, SimulationOptions::grid_orientation), and the world
// sees the rest mesh turned and moved: X_W = R (R0 (X_S - c) + c - c) + c + t =
// R R0 (X_S - c) + c + t (c the rest mesh's bounding-box centre). Gravity, the ground and the
// initial velocities go into S; positions, displacements and gradients come back.
// Elasticity, mass, drag and contact laws are the same in both frames (isotropic, rigid-
// invariant), so this is exactly the posed body's motion, and the pose needs no adjoint of its own
// inside the simulation.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <vector>

#include "core/fem/parameter_gradient.h"
#include "core/fem/physical_parameters.h"

namespace softid::fem {

class RestFrame {
 public:
  RestFrame() = default;  // the identity: no pose
  // @param mesh_from_grid R0, a proper rotation.
  RestFrame(const InitialPose& pose, const Eigen::Vector3d& centre_m,
            const Eigen::Matrix3d& mesh_from_grid = Eigen::Matrix3d::Identity());

  bool is_identity() const { return identity_; }
  const Eigen::Isometry3d& world_from_rest() const { return X_WS_; }

  // The parameters the simulation runs with in S: `world` with its gravity, ground and initial
  // velocities expressed in S and no pose.
  PhysicalParameters ToRest(const PhysicalParameters& world) const;
  // `gradient` holds d L / d of the S-frame gravity, ground, and initial velocities (as the
  // simulation's adjoint accumulates them); on return it holds d L / d of the `world` parameters,
  // with the pose's share through them added to its initial_pose entries.
  void ChainToWorld(const PhysicalParameters& world, ParameterGradient* gradient) const;

  // u_W = X_W - X for nodes at rest positions X (in S) displaced by u_S.
  void DisplacementToWorld(const std::vector<Eigen::Vector3d>& rest_positions_m,
                           const Eigen::VectorXd& u_rest_m, Eigen::VectorXd* u_world_m) const;
  // d L / d u_S from d L / d u_W at u_S (into *gradient_rest), adding d L / d pose through the
  // displacement to gradient->initial_pose_*.
  void DisplacementGradientToRest(const std::vector<Eigen::Vector3d>& rest_positions_m,
                                  const Eigen::VectorXd& u_rest_m,
                                  const Eigen::VectorXd& gradient_world,
                                  Eigen::VectorXd* gradient_rest,
                                  ParameterGradient* gradient) const;

 private:
  bool identity_ = true;
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();
  Eigen::Isometry3d X_WS_ = Eigen::Isometry3d::Identity();
  // d (R R0) / d rotation[k].
  std::array<Eigen::Matrix3d, 3> dR_{Eigen::Matrix3d::Zero(), Eigen::Matrix3d::Zero(),
                                     Eigen::Matrix3d::Zero()};
};

}  // namespace softid::fem
